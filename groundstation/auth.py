"""Who may do what on the ground service (issue 12 item 7): bearer tokens with two roles.

* ``operator``: everything (seed 003 Fig. 1: the one person who runs the team);
* ``observer``: read and the live stream only; a command answers 403 (and is audited).

Tokens come from a YAML file ``{operator: [tokens], observer: [tokens]}`` or are generated at start
(:func:`generate`) and printed. A token's name in the audit log is its role and a short fingerprint
(the token itself is never written).
"""

from __future__ import annotations

import hashlib
import hmac
from dataclasses import dataclass
from pathlib import Path

import yaml

from taskflight_common.tokens import role_tokens

ROLES = ("operator", "observer")


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
        self.by_role: dict[str, list[str]] = {}
        for role, tokens in by_role.items():
            if role not in ROLES:
                raise ValueError(f"tokens: unknown role {role!r} (roles: {', '.join(ROLES)})")
            if not isinstance(tokens, list) or not all(isinstance(t, str) and t.strip() for t in tokens):
                raise ValueError(f"tokens.{role}: expected a list of non-empty strings")
            self.by_role[role] = [t.strip() for t in tokens]
        if not self.by_role.get("operator"):
            raise ValueError("tokens.operator: at least one operator token is needed")
        seen: set[str] = set()
        for tokens in self.by_role.values():
            for t in tokens:
                if t in seen:
                    raise ValueError("tokens: a token is listed twice")
                seen.add(t)

    @classmethod
    def load(cls, path: str | Path) -> Tokens:
        """From a YAML file ``{operator: [...], observer: [...]}`` (ValueError naming what is wrong)."""
        try:
            data = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise ValueError(f"tokens file {path}: {exc}") from exc
        if not isinstance(data, dict):
            raise ValueError(f"tokens file {path}: expected a mapping {{operator: [...], observer: [...]}}")
        return cls({str(k): v for k, v in data.items()})

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


def bearer(header: str | None) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` header (None if absent or another scheme)."""
    if not header:
        return None
    scheme, _, credentials = header.strip().partition(" ")
    return credentials.strip() or None if scheme.lower() == "bearer" else None
