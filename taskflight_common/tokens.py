"""Bearer tokens made by Taskflight (the ground service's operator and observer tokens, the companions'
control tokens), and the tokens files the ground service, ``taskflight up`` and ``taskflight companion
--tokens`` read.

Each reader has its own roles: the ground service's are :data:`ROLES` (operator, observer); a
companion's control surface also has ``mission`` (:data:`COMPANION_ROLES`: a mission client activates
behaviors as the mission requester of seed 001, below the operator). A file naming a role its reader
does not take is refused naming the role and the reader's roles.

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
#: the roles of the ground service's tokens file: the operator commands (seed 003 Fig. 1), an observer
#: reads only
ROLES = ("operator", "observer")
#: the roles of a companion's control surface (``taskflight companion --tokens``), highest first: the
#: operator, the mission requester (seed 001 Definition 3), an observer (reads only). ``emergency`` is
#: no token's role: only the companion's own safety monitor requests as emergency, in-process.
COMPANION_ROLES = ("operator", "mission", "observer")


def check_tokens(by_role: Any, file: str | Path | None = None, roles: tuple[str, ...] = ROLES,
                 reader: str = "the ground service", need_operator: bool = True) -> dict[str, list[str]]:
    """``{operator: [...], observer: [...]}`` checked against ``reader``'s ``roles`` (at least one
    operator token unless ``need_operator`` is false; no token twice; each a non-empty string,
    stripped); :class:`ConfigError` naming the file, line and role otherwise."""
    fields = Fields(by_role, file=str(file) if file is not None else None)
    for key in by_role:
        if key not in roles:
            hint = " (mission tokens go in a companion's --tokens file)" if key == "mission" else ""
            raise fields.error(str(key), f"unknown role: {reader} takes {', '.join(roles)}{hint}")
    out: dict[str, list[str]] = {}
    seen: set[str] = set()
    for role in roles:
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
    if need_operator and not out["operator"]:
        raise fields.error("operator", "at least one operator token is needed")
    return out


def load_tokens(path: str | Path, roles: tuple[str, ...] = ROLES, reader: str = "the ground service",
                need_operator: bool = True) -> dict[str, list[str]]:
    """The tokens file, YAML ``{operator: [tokens], observer: [tokens]}`` (see :func:`check_tokens`);
    :class:`ConfigError` (a ValueError) as ``file:line: field: reason`` if it is unreadable or wrong."""
    try:
        data = load_yaml(path)
    except ConfigError as exc:
        raise ConfigError(exc.file, exc.line, exc.field, f"tokens file: {exc.reason}") from exc
    if not isinstance(data, dict):
        raise ConfigError(path, getattr(data, "start_line", None), None,
                          f"tokens file: expected a mapping {{{': [...], '.join(roles)}: [...]}}")
    return check_tokens(data, path, roles, reader, need_operator)
