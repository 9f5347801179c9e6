"""Bearer tokens made by Taskflight (the ground service's operator and observer tokens, the companions'
control token), and the tokens file both the ground service and ``taskflight up`` read.

A token is handed on command lines (``taskflight ground --companion-token T``) and pasted by operators,
so it must never look like an option: ``secrets.token_urlsafe`` starts with ``-`` once in 64 draws, and
argparse then takes it for a flag ("expected one argument"). :func:`new_token` draws until it does not.
"""

from __future__ import annotations

import secrets
from pathlib import Path
from typing import Any

from taskflight_common.yamlio import ConfigError, Fields, load_yaml


def new_token(nbytes: int = 24) -> str:
    """A URL-safe random token of ``nbytes`` bytes of entropy (minus the first character's sign bit)
    that does not start with ``-``."""
    while True:
        token = secrets.token_urlsafe(nbytes)
        if not token.startswith("-"):
            return token


def role_tokens() -> dict[str, list[str]]:
    """One new operator and one new observer token, as a tokens file holds them
    (``{operator: [...], observer: [...]}``)."""
    return {"operator": [new_token()], "observer": [new_token()]}


#: where the companion's control token is read from (``taskflight companion``, the ground service toward
#: the companions, ``taskflight up`` for its children): other users cannot read a process's environment
TOKEN_ENV = "TASKFLIGHT_CONTROL_TOKEN"
#: the roles of a tokens file: the operator commands (seed 003 Fig. 1), an observer reads only
ROLES = ("operator", "observer")


def check_tokens(by_role: Any, file: str | Path | None = None) -> dict[str, list[str]]:
    """``{operator: [...], observer: [...]}`` checked (at least one operator token; no token twice; each
    a non-empty string, stripped); :class:`ConfigError` naming the file, line and role otherwise."""
    fields = Fields(by_role, file=str(file) if file is not None else None)
    for key in by_role:
        if key not in ROLES:
            raise fields.error(str(key), f"unknown role (roles: {', '.join(ROLES)})")
    out: dict[str, list[str]] = {}
    seen: set[str] = set()
    for role in ROLES:
        tokens = fields.raw(role, [])
        if tokens is None:
            tokens = []
        if not isinstance(tokens, list) or not all(isinstance(t, str) and t.strip() for t in tokens):
            raise fields.error(role, "expected a list of non-empty strings")
        out[role] = [t.strip() for t in tokens]
        for t in out[role]:
            if t in seen:
                raise fields.error(role, "a token is listed twice")
            seen.add(t)
    if not out["operator"]:
        raise fields.error("operator", "at least one operator token is needed")
    return out


def load_tokens(path: str | Path) -> dict[str, list[str]]:
    """The tokens file, YAML ``{operator: [tokens], observer: [tokens]}`` (see :func:`check_tokens`);
    :class:`ConfigError` (a ValueError) as ``file:line: field: reason`` if it is unreadable or wrong."""
    try:
        data = load_yaml(path)
    except ConfigError as exc:
        raise ConfigError(exc.file, exc.line, exc.field, f"tokens file: {exc.reason}") from exc
    if not isinstance(data, dict):
        raise ConfigError(path, getattr(data, "start_line", None), None,
                          "tokens file: expected a mapping {operator: [...], observer: [...]}")
    return check_tokens(data, path)
