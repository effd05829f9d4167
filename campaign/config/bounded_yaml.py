"""Bounded YAML loading: a size limit on the file and a limit on the expanded node count (alias bombs).

PyYAML builds shared objects for aliases, so a "billion laughs" document loads quickly but every walk over
it (validation, freezing, hashing) is exponential. The expanded size is counted on the composed node graph
(memoised per node, so the count itself is linear in the document) before anything is constructed.
"""
from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import yaml

from campaign.errors import ConfigError

MAX_CONFIG_BYTES = 1 << 20          # 1 MiB: a cell config is a few kB
MAX_EXPANDED_NODES = 100_000        # after alias expansion; the shipped configs have ~600


def read_limited(path: str | Path, limit: int = MAX_CONFIG_BYTES) -> bytes:
    """The file's bytes; ``ConfigError`` if it is larger than ``limit`` (never reads more than limit + 1)."""
    with open(path, "rb") as fh:
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise ConfigError(str(path), "", f"file larger than {limit // 1024} KiB: not a campaign config")
    return data


def load_limited(text: str, loader_cls: type, file: str) -> Any:
    """Safe-load one YAML document with ``loader_cls``, refusing more than ``MAX_EXPANDED_NODES`` nodes after
    alias expansion and recursive aliases. YAML syntax errors propagate as ``yaml.YAMLError``."""
    if len(text) > MAX_CONFIG_BYTES:
        raise ConfigError(file, "", f"file larger than {MAX_CONFIG_BYTES // 1024} KiB: not a campaign config")
    fast = _with_libyaml(loader_cls)
    if fast is not None:
        try:
            return _load(text, fast, file)
        except yaml.YAMLError:
            pass            # parse again in pure Python: the same acceptance and the same wording of the error
    return _load(text, loader_cls, file)


@functools.cache
def _with_libyaml(loader_cls: type) -> type | None:
    """``loader_cls`` with libyaml's C parser and composer (about 10 x faster than the pure-Python ones; the
    constructor, so the values and their checks, stays ``loader_cls``'s), or None without libyaml."""
    if not getattr(yaml, "__with_libyaml__", False) or not issubclass(loader_cls, yaml.SafeLoader):
        return None

    def __init__(self, stream):
        yaml.cyaml.CParser.__init__(self, stream)
        yaml.constructor.SafeConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)
    return type(f"{loader_cls.__name__}LibYaml", (yaml.cyaml.CParser, loader_cls), {"__init__": __init__})


def _load(text: str, loader_cls: type, file: str) -> Any:
    loader = loader_cls(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        try:
            size = expanded_size(node)
        except ConfigError as exc:
            raise ConfigError(file, "", exc.message) from None
        if size > MAX_EXPANDED_NODES:
            raise ConfigError(file, "", f"YAML expands to more than {MAX_EXPANDED_NODES} nodes through aliases "
                                        "(alias bomb?): write the values out")
        try:
            return loader.construct_document(node)
        except ValueError:              # an integer of more digits than Python converts (sys.get_int_max_str_digits)
            raise ConfigError(file, _long_number_at(node), "a number with too many digits to read: not a "
                                                            "campaign config value") from None
    except RecursionError:
        raise ConfigError(file, "", "YAML nested too deeply") from None
    finally:
        loader.dispose()


def expanded_size(root: yaml.Node) -> int:
    """Number of nodes after alias expansion (capped just above the limit); ConfigError on a recursive alias."""
    memo: dict[int, int] = {}
    active: set[int] = set()

    def size(node: yaml.Node) -> int:
        key = id(node)
        if key in memo:
            return memo[key]
        if key in active:
            raise ConfigError("", "", "recursive YAML alias")
        active.add(key)
        total = 1
        if isinstance(node, yaml.SequenceNode):
            children = node.value
        elif isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        else:
            children = []
        for child in children:
            total += size(child)
            if total > MAX_EXPANDED_NODES:
                break
        active.discard(key)
        memo[key] = min(total, MAX_EXPANDED_NODES + 1)
        return memo[key]

    return _iterative_guard(size, root)


def _iterative_guard(size, root) -> int:
    """Deeply nested documents would exhaust the recursion limit: report them as too deep."""
    try:
        return size(root)
    except RecursionError:
        raise ConfigError("", "", "YAML nested too deeply") from None


def _long_number_at(root: yaml.Node) -> str:
    """``line L, column C`` of the first scalar too long to be a number ('' when none is found)."""
    seen: set[int] = set()
    stack = [root]
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.ScalarNode):
            if len(node.value) > 1000 and node.value.lstrip("+-").replace("_", "")[:1].isdigit():
                return f"line {node.start_mark.line + 1}, column {node.start_mark.column + 1}"
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(reversed(node.value))
        elif isinstance(node, yaml.MappingNode):
            stack.extend(n for pair in reversed(node.value) for n in reversed(pair))
    return ""
