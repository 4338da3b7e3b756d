"""YAML sources that remember where each key stands, and pydantic errors turned into ``file:line: key:`` lines.

Shared by the scenario and campaign loaders, so that every configuration error names its file, line
and key in the same way.
"""
from __future__ import annotations

import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from feeddrive.cosim.errors import ScenarioError, format_path

#: a key's path in a YAML document, e.g. ``("nc", "program", 2, "rapid")``
KeyPath = tuple[Any, ...]


#: largest scenario or campaign file [bytes]: a real one is a few kB
MAX_BYTES = 1 << 20
#: largest number of YAML nodes after alias expansion ("billion laughs": a few hundred bytes of nested
#: aliases expand to 10^9 nodes, which the key map and the validation would walk one by one)
MAX_NODES = 100_000
#: deepest nesting of YAML collections (PyYAML composes recursively)
MAX_DEPTH = 100


def _char_at(text: str, line: int, column: int) -> str:
    """The character at a 0-based line and column of ``text`` ('' past its end)."""
    lines = text.splitlines()
    return lines[line][column:column + 1] if 0 <= line < len(lines) else ""


def read_yaml(path: Path, kind: str = "scenario", error: type[ValueError] = ScenarioError
              ) -> tuple[Any, dict[KeyPath, int]]:
    """The data of a YAML file and its key path -> line map.

    Parameters
    ----------
    path : Path
    kind : str
        What the file is, for the messages (``scenario``, ``campaign``).
    error : exception class
        Raised with one line naming the file (and line) and what was expected.

    Raises
    ------
    error
        Unreadable, larger than ``MAX_BYTES``, not UTF-8, invalid YAML, nested deeper than
        ``MAX_DEPTH`` or expanding (aliases) to more than ``MAX_NODES`` nodes.
    """
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise error(f"{path}: {kind} file of {size} bytes; expected at most {MAX_BYTES} bytes")
        raw = path.read_bytes()
    except OSError as exc:
        raise error(f"{path}: cannot read {kind} file ({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise error(f"{path}:{line}: byte 0x{raw[exc.start]:02x} is not UTF-8; expected a UTF-8 {kind} file") from None
    try:
        _check_depth(text, path, error)
        root = yaml.compose(text, Loader=_LOADER)
        if root is not None:
            _check_size(root, path, error)
        data = yaml.load(text, Loader=_LOADER)  # noqa: S506 - a safe loader (CSafeLoader or SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark else str(path)
        problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
        if mark is not None and _char_at(text, mark.line, mark.column) == "\t":
            # PyYAML's "found character that cannot start any token" (its C loader does not say which)
            raise error(f"{where}: a tab character (column {mark.column + 1}): YAML indents with spaces; "
                        "replace the tab by spaces") from None
        if "nesting depth" in problem:  # PyYAML >= 6.0.3 has its own depth limit, met before ours
            raise error(f"{where}: YAML nested too deeply; expected at most {MAX_DEPTH} levels") from None
        raise error(f"{where}: invalid YAML: {problem}") from None
    except error:
        raise
    except RecursionError:
        raise error(f"{path}: YAML nested too deeply; expected at most {MAX_DEPTH} levels") from None
    except (ValueError, TypeError, OverflowError) as exc:  # constructors: timestamps, huge ints, bad keys
        raise error(f"{path}: invalid YAML value: {' '.join(str(exc).split())}") from None
    lines: dict[KeyPath, int] = {}
    if root is not None:
        _line_map(root, (), lines)
    return data, lines


#: libyaml's loader when PyYAML was built with it (faster, and not recursive in Python)
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def _check_depth(text: str, path: Path, error: type[ValueError]) -> None:
    """Refuse a document nested deeper than ``MAX_DEPTH``, from the parser's events (no recursion, and
    it stops at the first level too deep instead of composing thousands)."""
    depth = 0
    for event in yaml.parse(text, Loader=_LOADER):
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_DEPTH:
                raise error(f"{path}:{event.start_mark.line + 1}: YAML nested too deeply; expected at most "
                            f"{MAX_DEPTH} levels")
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


def _check_unique(node: yaml.MappingNode, path: Path, error: type[ValueError]) -> None:
    """Refuse a key given twice in one mapping: YAML loaders keep the last one silently (a second ``sensors:``
    replaced the first whole, its faults and seed gone without a word)."""
    seen: dict[tuple[str, str], int] = {}
    for key, _ in node.value:
        if isinstance(key, yaml.ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
            line = key.start_mark.line + 1
            if (key.tag, key.value) in seen:
                raise error(f"{path}:{line}: {key.value}: duplicate key (first at line {seen[key.tag, key.value]}); "
                            "expected each key once in a mapping (a YAML loader keeps only the last)")
            seen[key.tag, key.value] = line


def _check_size(root: yaml.Node, path: Path, error: type[ValueError]) -> None:
    """Refuse a document too deep, or too large once its aliases are expanded (linear time: a node
    shared through aliases is counted from a memo, never walked twice)."""
    sizes: dict[int, int] = {}

    def size(node: yaml.Node, depth: int) -> int:
        if depth > MAX_DEPTH:
            raise error(f"{path}:{node.start_mark.line + 1}: YAML nested too deeply; expected at most "
                        f"{MAX_DEPTH} levels")
        key = id(node)
        if key not in sizes:
            sizes[key] = -1  # in progress: a recursive alias
            children = [n for kv in node.value for n in kv] if isinstance(node, yaml.MappingNode) else \
                node.value if isinstance(node, yaml.SequenceNode) else []
            if isinstance(node, yaml.MappingNode):
                _check_unique(node, path, error)
            total = 1 + sum(size(c, depth + 1) for c in children)
            sizes[key] = total
        elif sizes[key] < 0:
            raise error(f"{path}:{node.start_mark.line + 1}: recursive YAML alias; expected a tree")
        if sizes[key] > MAX_NODES:
            raise error(f"{path}:{node.start_mark.line + 1}: YAML aliases expand to more than {MAX_NODES} "
                        "values; expected a plain scenario (expand fewer aliases)")
        return sizes[key]

    size(root, 0)


def _line_map(node: yaml.Node, path: KeyPath, out: dict[KeyPath, int]) -> None:
    out.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for key, value in node.value:
            sub = path + (key.value,)
            out[sub] = key.start_mark.line + 1
            _line_map(value, sub, out)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _line_map(item, path + (i,), out)




def located_error(source: str, lines: Mapping[KeyPath, int], path: KeyPath, message: str) -> ScenarioError:
    path = tuple(path)
    line = next((lines[path[:k]] for k in range(len(path), -1, -1) if path[:k] in lines), None)
    where = f"{source}:{line}" if line else source
    # a key with a newline or a control character is shown as its repr: the message stays one line
    key = f" {format_path(tuple(p if not isinstance(p, str) or p.isprintable() else repr(p) for p in path))}:" \
        if path else ""
    return ScenarioError(f"{where}:{key} {message}")


def _allowed_keys(model: type, loc: KeyPath) -> list[str]:
    """Field names (aliases) of the pydantic model found at ``loc`` inside ``model``, if any."""
    candidates = [model]
    for part in loc:
        nxt = []
        for tp in candidates:
            for t in _unwrap(tp):
                if isinstance(t, type) and issubclass(t, BaseModel) and isinstance(part, str):
                    f = next((f for n, f in t.model_fields.items() if (f.alias or n) == part), None)
                    if f is not None:
                        nxt.append(f.annotation)
                elif typing.get_origin(t) in (list, tuple) and isinstance(part, int):
                    nxt.extend(typing.get_args(t)[:1])
                elif typing.get_origin(t) is dict:
                    nxt.extend(typing.get_args(t)[1:2])
        candidates = nxt
    return sorted({f.alias or n for tp in candidates for t in _unwrap(tp)
                   if isinstance(t, type) and issubclass(t, BaseModel) for n, f in t.model_fields.items()})


def _unwrap(tp: Any) -> list[Any]:
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return [a for x in typing.get_args(tp) for a in _unwrap(x)]
    if typing.get_origin(tp) is typing.Annotated:
        return _unwrap(typing.get_args(tp)[0])
    return [tp]


def from_validation(exc: ValidationError, data: Any, source: str, lines: Mapping[KeyPath, int],
                     model: type, prefix: KeyPath = ()) -> ScenarioError:
    errors = exc.errors(include_url=False)
    e = errors[0]
    loc = _data_path(data, e["loc"])
    if e["type"] == "extra_forbidden":
        allowed = _allowed_keys(model, loc[:-1])
        message = f"unknown key {loc[-1]!r}" + (f"; expected one of: {', '.join(allowed)}" if allowed else "")
    elif e["type"] == "missing":
        message = "missing required key"
    else:
        # a union reports one error per member at the same key: say every alternative
        same = [x for x in errors if _data_path(data, x["loc"]) == loc and x["type"] != "value_error"]
        text = " or ".join(dict.fromkeys(x["msg"].removeprefix("Input should be ") for x in same)) \
            if len(same) > 1 else e["msg"].removeprefix("Value error, ")
        text = f"Input should be {text}" if len(same) > 1 else text
        got = repr(e.get("input"))
        message = text if len(got) > 60 or e["type"] == "value_error" else f"{text}, got {got}"
        errors = [x for x in errors if x not in same[1:]]
    more = f" (and {len(errors) - 1} more problem{'s' * (len(errors) > 2)})" if len(errors) > 1 else ""
    return located_error(source, lines, prefix + loc, message + more)


def _data_path(data: Any, loc: KeyPath) -> KeyPath:
    """Drop the union-member tags pydantic puts in ``loc`` ('str', "literal['all']", ...): keep the parts
    that index into the data, and a last part that names a missing key."""
    path: list = []
    for k, part in enumerate(loc):
        if isinstance(data, dict) and part in data:
            data = data[part]
        elif isinstance(data, list) and isinstance(part, int) and part < len(data):
            data = data[part]
        elif k < len(loc) - 1 or not isinstance(data, dict):
            continue
        path.append(part)
    return tuple(path)
