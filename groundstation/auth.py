"""Who may do what on the ground service: bearer tokens with two roles.

* ``operator``: everything (seed 003 Fig. 1: the one person who runs the team);
* ``observer``: read and the live stream only; a command answers 403 (and is audited).

Tokens come from a YAML file ``{operator: [tokens], observer: [tokens]}``
(:func:`taskflight_common.tokens.load_tokens`, the same rules as ``taskflight up``) or are generated at
start (:func:`generate`) and printed. A token's name in the audit log is its role and a short fingerprint
(the token itself is never written).
"""

from __future__ import annotations

import hashlib
import hmac
from dataclasses import dataclass
from pathlib import Path

import yaml

from taskflight_common.tokens import ROLES, check_tokens, load_tokens, role_tokens

__all__ = ["ROLES", "Principal", "Tokens", "fingerprint"]


@dataclass(frozen=True)
class Principal:
    """An authenticated caller."""

    role: str
    name: str

    @property
    def may_command(self) -> bool:
        return self.role == "operator"


def fingerprint(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()[:8]


class Tokens:
    """The accepted tokens by role; :meth:`check` is constant-time per token."""

    def __init__(self, by_role: dict[str, list[str]]) -> None:
        self.by_role: dict[str, list[str]] = {r: t for r, t in check_tokens(by_role).items() if t}

    @classmethod
    def load(cls, path: str | Path) -> Tokens:
        """From a YAML file ``{operator: [...], observer: [...]}`` (ValueError: file, line and field)."""
        return cls(load_tokens(path))

    @classmethod
    def generate(cls) -> Tokens:
        return cls(role_tokens())

    def check(self, token: str | None) -> Principal | None:
        """The caller holding ``token``, or None."""
        if not token:
            return None
        given = token.strip().encode("utf-8")
        found: Principal | None = None
        for role, tokens in self.by_role.items():
            for t in tokens:
                if hmac.compare_digest(given, t.encode("utf-8")):
                    found = Principal(role, f"{role}:{fingerprint(t)}")
        return found

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.by_role, sort_keys=False)

