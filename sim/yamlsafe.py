"""YAML read safely for sensor descriptions: no arbitrary objects, no repeated keys, and bounded size.

A description too long, or whose aliases expand it past ``MAX_YAML_NODES`` values (an alias bomb expands to
billions), is refused before it is built: validating and printing an expanded bomb costs gigabytes.
"""

from __future__ import annotations

from typing import Any

import yaml
from rollcam.common.errors import ConfigError

MAX_YAML_BYTES = 1 << 20
"""Largest sensor description read (the shipped ones are ~6 KB)."""
MAX_YAML_NODES = 100_000
"""Most values a description may expand to with its aliases resolved (an alias bomb expands to billions)."""


class _StrictLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """(C)SafeLoader that rejects a repeated mapping key instead of silently keeping the last one."""


def _mapping_no_duplicates(loader: _StrictLoader, node: yaml.MappingNode) -> dict:
    loader.flatten_mapping(node)
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node)
        if key in seen:
            raise yaml.constructor.ConstructorError(None, None, f"duplicate key {key!r}", key_node.start_mark)
        seen.add(key)
    return loader.construct_mapping(node, deep=True)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping_no_duplicates)


def _expanded_size(node: yaml.Node, memo: dict[int, int]) -> int:
    """How many values ``node`` stands for once every alias is resolved (counted once per shared node)."""
    key = id(node)
    if key not in memo:
        memo[key] = 0  # a node that contains itself is refused by the constructor; count it as nothing here
        children = node.value if isinstance(node, (yaml.SequenceNode, yaml.MappingNode)) else ()
        flat = [n for pair in children for n in pair] if isinstance(node, yaml.MappingNode) else children
        memo[key] = 1 + sum(_expanded_size(n, memo) for n in flat)
    return memo[key]


def _check_size(text: str, label: str) -> None:
    """Refuse a description too long, or whose aliases expand it beyond ``MAX_YAML_NODES`` values, before it is
    built: validating (and printing) an expanded alias bomb costs gigabytes."""
    if len(text) > MAX_YAML_BYTES:
        raise ConfigError(f"{label}: {len(text):,} characters; a sensor description has at most {MAX_YAML_BYTES:,}")
    try:
        root = yaml.compose(text, Loader=_StrictLoader)
        n = 0 if root is None else _expanded_size(root, {})
    except yaml.YAMLError:
        return  # the load below reports the syntax error with its position
    except RecursionError:
        raise ConfigError(f"{label}: values nested too deeply for a sensor description") from None
    if n > MAX_YAML_NODES:
        raise ConfigError(f"{label}: its aliases expand it to {n:,} values; a sensor description has at most "
                          f"{MAX_YAML_NODES:,}")


def read_yaml(text: str, label: str) -> Any:
    """The plain data of ``text`` (``label`` names it in errors); ConfigError when it is too big or not YAML."""
    _check_size(text, label)
    try:
        return yaml.load(text, Loader=_StrictLoader)  # a SafeLoader subclass: builds no arbitrary objects
    except yaml.YAMLError as e:
        raise ConfigError(f"{label}: not valid YAML: {e}".replace("<unicode string>", label)) from None
