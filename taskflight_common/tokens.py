"""Bearer tokens made by Taskflight (the ground service's operator and observer tokens, the companions'
control token).

A token is handed on command lines (``taskflight ground --companion-token T``) and pasted by operators,
so it must never look like an option: ``secrets.token_urlsafe`` starts with ``-`` once in 64 draws, and
argparse then takes it for a flag ("expected one argument"). :func:`new_token` draws until it does not.
"""

from __future__ import annotations

import secrets


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
