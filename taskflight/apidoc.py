"""``docs/http-api.md``, generated from the OpenAPI schemas of the two HTTP services.

The ground service (:func:`groundstation.app.create_app`, the operator's team control and process
monitor, seed 003 Fig. 1) and the companion's control surface (:func:`companion.http.app.create_app`,
the QAPI of seed 000 Sec. V with the executive, mission and team layers) each describe every route
with pydantic models. This module renders, for each service, every path and method with its summary,
its path and query parameters, its request body's model and its answers' models, and then the fields
of every model named, as Markdown. The output depends only on the code (paths and models are sorted),
so ``tests/test_docs_api.py`` can regenerate it and fail when the checked-in page is stale.

Run ``taskflight docs api`` (or ``python -m taskflight.apidoc``) to rewrite ``docs/http-api.md``;
``--check`` only compares.

Each application is built with stand-ins (:class:`unittest.mock.MagicMock`) for the objects its
routers close over (the node, the executive layer, the mission service, the team member, the ground
service): building a router reads nothing from them, and the schema is all that is used here. Every
optional part of the companion is served, so its page lists the routes of a companion with behaviors,
missions and a team.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any
from unittest.mock import MagicMock

#: where the page lives, from the repository root
DEFAULT_OUT = Path(__file__).resolve().parent.parent / "docs" / "http-api.md"
#: the command that regenerates it (named in the page and by the test)
REGENERATE = "taskflight docs api"

_METHODS = ("get", "put", "post", "delete", "patch")


def companion_schema() -> dict[str, Any]:
    """The companion control surface's OpenAPI document, every optional layer served."""
    from companion.http.app import create_app

    app = create_app(MagicMock(), behaviors=MagicMock(), missions=MagicMock(), team_member=MagicMock())
    return app.openapi()


def ground_schema() -> dict[str, Any]:
    """The ground service's OpenAPI document."""
    from groundstation.app import create_app

    return create_app(MagicMock()).openapi()


def _ref_names(schema: dict[str, Any] | None) -> list[str]:
    """The component names a schema refers to (through $ref, unions and arrays), in order."""
    if not schema:
        return []
    if "$ref" in schema:
        return [schema["$ref"].rsplit("/", 1)[1]]
    names: list[str] = []
    for key in ("oneOf", "anyOf", "allOf"):
        for sub in schema.get(key, []):
            names += [n for n in _ref_names(sub) if n not in names]
    if schema.get("type") == "array":
        names += [f"list of {n}" for n in _ref_names(schema.get("items"))]
    if "additionalProperties" in schema and isinstance(schema["additionalProperties"], dict):
        names += [f"map of {n}" for n in _ref_names(schema["additionalProperties"])]
    return names


def _type_of(schema: dict[str, Any]) -> str:
    """A short type for a field or parameter: a model name, a JSON type, a union, an enum."""
    if "$ref" in schema:
        return str(schema["$ref"].rsplit("/", 1)[1])
    for key in ("anyOf", "oneOf"):
        if key in schema:
            parts = [_type_of(s) for s in schema[key]]
            return " or ".join(dict.fromkeys(parts))
    if "enum" in schema:
        return " / ".join(repr(v) if not isinstance(v, str) else v for v in schema["enum"])
    if "const" in schema:
        return repr(schema["const"]) if not isinstance(schema["const"], str) else str(schema["const"])
    kind = schema.get("type")
    if kind == "array":
        return f"list of {_type_of(schema.get('items', {}))}"
    if kind == "object" and isinstance(schema.get("additionalProperties"), dict):
        return f"map of {_type_of(schema['additionalProperties'])}"
    return str(kind) if kind else "any"


def _cell(text: str) -> str:
    """One Markdown table cell: one line, pipes escaped."""
    return " ".join(text.split()).replace("|", "\\|")


def _body_names(op: dict[str, Any]) -> str:
    body = op.get("requestBody")
    if not body:
        return "-"
    names: list[str] = []
    for media, content in sorted(body.get("content", {}).items()):
        found = _ref_names(content.get("schema"))
        label = ", ".join(found) if found else _type_of(content.get("schema", {}))
        names.append(label if media == "application/json" else f"{label} ({media})")
    return "; ".join(names) or "-"


def _answer_names(op: dict[str, Any]) -> str:
    parts: list[str] = []
    for code, answer in sorted(op.get("responses", {}).items()):
        content = answer.get("content", {}).get("application/json", {})
        found = _ref_names(content.get("schema"))
        label = ", ".join(found) if found else (_type_of(content["schema"]) if content.get("schema") else "-")
        parts.append(f"{code} {label}")
    return "; ".join(parts)


def _params(op: dict[str, Any]) -> str:
    out = []
    for p in op.get("parameters", []):
        star = "" if p.get("required") else "?"
        out.append(f"{p['in']} `{p['name']}{star}`: {_type_of(p.get('schema', {}))}")
    return "; ".join(out) or "-"


def _models_used(doc: dict[str, Any]) -> list[str]:
    """Every component reachable from the paths, sorted."""
    schemas = doc.get("components", {}).get("schemas", {})
    seen: set[str] = set()

    def walk(node: Any) -> None:
        if isinstance(node, dict):
            ref = node.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/components/schemas/"):
                name = ref.rsplit("/", 1)[1]
                if name not in seen:
                    seen.add(name)
                    walk(schemas.get(name))
            for value in node.values():
                walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)

    walk(doc.get("paths", {}))
    return sorted(seen)


def _operations(doc: dict[str, Any]) -> Iterable[tuple[str, str, dict[str, Any]]]:
    for path in sorted(doc.get("paths", {})):
        ops = doc["paths"][path]
        for method in _METHODS:
            if method in ops:
                yield path, method, ops[method]


def render_service(title: str, factory: str, doc: dict[str, Any]) -> str:
    """One service's section: its routes, then its models with their fields."""
    lines = [f"## {title}", "", f"Built by `{factory}`; served at `/openapi.json` and `/docs` by the "
             "running service.", "",
             "| method | path | what it does | parameters | request body | answers |",
             "|---|---|---|---|---|---|"]
    for path, method, op in _operations(doc):
        summary = (op.get("description") or "").strip().split("\n\n")[0] or op.get("summary", "")
        lines.append(f"| {method.upper()} | `{path}` | {_cell(summary)} | {_cell(_params(op))} | "
                     f"{_cell(_body_names(op))} | {_cell(_answer_names(op))} |")
    lines += ["", f"### {title}: models", ""]
    schemas = doc.get("components", {}).get("schemas", {})
    for name in _models_used(doc):
        schema = schemas[name]
        lines.append(f"**{name}**" + (f": {_cell(schema['description'].split(chr(10) * 2)[0])}"
                                       if schema.get("description") else ""))
        props = schema.get("properties", {})
        if props:
            required = set(schema.get("required", []))
            fields = [f"`{k}{'' if k in required else '?'}` {_type_of(v)}" for k, v in props.items()]
            lines.append("")
            lines.append(_cell("; ".join(fields)))
        elif "enum" in schema or "oneOf" in schema or "anyOf" in schema:
            lines.append("")
            lines.append(_cell(_type_of(schema)))
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def render() -> str:
    """The whole page, deterministic for a given code base."""
    head = [
        "# The HTTP APIs",
        "",
        f"<!-- GENERATED by `{REGENERATE}` (taskflight/apidoc.py) from the services' OpenAPI schemas. "
        "Do not edit by hand. -->",
        "",
        "Two services speak HTTP: the **ground service** (`taskflight ground`, also started by "
        "`taskflight up`; the operator's team control and web UI) and each vehicle's **companion** "
        "(`taskflight companion`, its control surface on 127.0.0.1:8765 by default). Both answer every "
        "refusal with `{\"error\": \"...\"}` and change nothing; both take `Authorization: Bearer TOKEN` "
        "(the ground service always, its roles in [operator-guide.md](operator-guide.md); the companion "
        "when started with a control token). A `?` after a name marks it optional. The ground service "
        "also serves the WebSocket `/api/ws` (the live fleet snapshot and the joystick; the token as the "
        "query parameter `token` or in the first message), which OpenAPI does not describe.",
        "",
    ]
    return "\n".join(head) + "\n" + "\n".join([
        render_service("Ground service", "groundstation.app.create_app", ground_schema()),
        render_service("Companion control surface", "companion.http.app.create_app", companion_schema()),
    ])


def add_docs_arguments(parser: argparse.ArgumentParser) -> None:
    """``taskflight docs api [--out FILE] [--check]``."""
    dsub = parser.add_subparsers(dest="docs_command", required=True, metavar="SUBCOMMAND")
    add_api_options(dsub.add_parser("api", help="write docs/http-api.md from the services' OpenAPI schemas"))


def add_api_options(parser: argparse.ArgumentParser) -> None:
    """``--out FILE``, ``--check``."""
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="the page to write (default docs/http-api.md)")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if the page is not current")


def run_docs(args: argparse.Namespace) -> int:
    """Write (or with ``--check`` compare) the generated page; 0 done or current, 1 stale."""
    text = render()
    out: Path = args.out
    if args.check:
        current = out.read_text(encoding="utf-8") if out.exists() else ""
        if current != text:
            print(f"{out} is not current: run `{REGENERATE}`", file=sys.stderr)
            return 1
        return 0
    out.write_text(text, encoding="utf-8")
    print(out)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m taskflight.apidoc", description=__doc__.splitlines()[0])
    add_api_options(parser)
    return run_docs(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
