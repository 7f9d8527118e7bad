"""Typed configs: dataclasses loaded from YAML, with ``a.b=value`` overrides from the command line.

A config is a (frozen or not) dataclass whose fields are annotated with the supported types:
``int``, ``float`` (an integer value is accepted and converted), ``bool``, ``str``, ``pathlib.Path``
(from a string), ``typing.Literal[...]``, ``Optional[X]`` / ``X | None``, ``list[X]``,
``tuple[X, ...]`` / ``tuple[X, Y]``, ``dict[str, X]``, ``typing.Any`` and nested dataclasses.
A YAML mapping fills the fields it names; the others keep their defaults. Unknown keys and values of
the wrong type raise :class:`~loosefit.errors.InputError` naming the file and the dotted key.

Overrides are ``"key.sub=value"`` strings whose value is parsed as a YAML scalar or flow collection
(``lr=1e-3``, ``stages.low.epochs=20``, ``sizes=[64, 64]``, ``name=null``). A dotted key walks into
nested dataclasses and ``dict`` fields (creating missing dictionary entries); the result is
type-checked like a file.

YAML 1.1 reads ``1e-3`` (no dot) as a string; this module's loader reads it as a float, in files and
in overrides alike. Every YAML file loosefit reads goes through :func:`load_yaml`: a key given twice in one
mapping is an error naming the file, the key and its lines (plain YAML keeps the last value silently). It
refuses hostile documents before building them: more than :data:`MAX_YAML_CHARS` characters, nesting deeper
than :data:`MAX_YAML_DEPTH`, or aliases that expand to more than :data:`MAX_YAML_VALUES` values (a "billion
laughs" bomb) or refer to themselves.
"""

from __future__ import annotations

import dataclasses
import re
import reprlib
import types
import typing
from pathlib import Path
from typing import Any, Iterable, TypeVar

import yaml

from loosefit.errors import InputError
from loosefit.paths import atomic_path

T = TypeVar("T")

__all__ = [
    "load_config",
    "config_from_dict",
    "apply_overrides",
    "config_to_dict",
    "save_config",
    "parse_override",
    "load_yaml",
    "read_yaml_text",
]


class _DuplicateKey(yaml.YAMLError):
    """A mapping names one key twice (YAML itself would silently keep the last value)."""

    def __init__(self, key: Any, line: int, first: int):
        self.key, self.line, self.first = key, line, first
        super().__init__(f"duplicate key {key!r} on line {line} (first on line {first})")


#: The longest YAML document read (characters); loosefit's largest plans are about 10 KB.
MAX_YAML_CHARS = 4 * 1024 * 1024
#: The deepest nesting of mappings and lists in a YAML document, and in what its aliases expand to.
MAX_YAML_DEPTH = 64
#: The most values (scalars, lists and mappings) a YAML document may hold once its aliases are expanded.
MAX_YAML_VALUES = 200_000


class _TooLarge(yaml.YAMLError):
    """A document beyond one of the reader's limits (its message names the limit)."""


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def _check_expansion(root: yaml.Node) -> None:
    """Refuse a node graph whose aliases expand beyond :data:`MAX_YAML_VALUES` values or :data:`MAX_YAML_DEPTH`
    levels, or refer to themselves; each node is visited once (no expansion, no recursion)."""
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    open_: set[int] = set()  # the nodes whose subtree is being visited (ancestors of the current one)
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, closing = stack.pop()
        key = id(node)
        if closing:
            open_.discard(key)
            kids = _children(node)
            size[key] = 1 + sum(size[id(k)] for k in kids)
            depth[key] = 1 + max((depth[id(k)] for k in kids), default=0)
            if size[key] > MAX_YAML_VALUES:
                raise _TooLarge(f"its aliases expand to more than {MAX_YAML_VALUES:,} values (a YAML bomb?); "
                                f"the limit is loosefit.config.MAX_YAML_VALUES")
            if depth[key] > MAX_YAML_DEPTH:
                raise _TooLarge(f"its aliases expand to more than {MAX_YAML_DEPTH} levels of nesting; the limit is "
                                "loosefit.config.MAX_YAML_DEPTH")
            continue
        if key in size:
            continue
        if key in open_:
            raise _TooLarge(f"an alias refers to the value it is in (line {node.start_mark.line + 1}): a value "
                            "that contains itself")
        open_.add(key)
        stack.append((node, True))
        stack.extend((k, False) for k in _children(node) if id(k) not in size)


class _Loader(yaml.SafeLoader):
    """Safe YAML loader that also reads exponent floats without a dot (``1e-3``) as floats, refuses a mapping
    that names a key twice, and refuses nesting and alias expansion beyond the module's limits."""

    _depth = 0

    def _too_deep(self, levels: int) -> None:
        if levels > MAX_YAML_DEPTH:  # checked while scanning: the scanner reads ahead through unclosed brackets
            raise _TooLarge(f"nested more than {MAX_YAML_DEPTH} levels deep (line {self.get_mark().line + 1}); the "
                            "limit is loosefit.config.MAX_YAML_DEPTH")

    def fetch_flow_collection_start(self, TokenClass):
        self._too_deep(self.flow_level + 1)
        super().fetch_flow_collection_start(TokenClass)

    def add_indent(self, column):
        added = super().add_indent(column)
        self._too_deep(len(self.indents))
        return added

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                mark = self.peek_event().start_mark
                raise _TooLarge(f"nested more than {MAX_YAML_DEPTH} levels deep (line {mark.line + 1}); the limit is "
                                "loosefit.config.MAX_YAML_DEPTH")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def compose_document(self):
        node = super().compose_document()
        if node is not None:
            _check_expansion(node)
        return node

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # `<<: *base` entries may be overridden by the mapping's own keys
                key = self.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                try:
                    if key in seen:
                        raise _DuplicateKey(key, line, seen[key])
                except TypeError:
                    continue  # an unhashable key: SafeLoader's own error says so
                seen[key] = line
        return super().construct_mapping(node, deep=deep)


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def load_yaml(text: str, source: str | Path | None = None) -> Any:
    """Parse YAML text with the config loader (safe: plain data only); a syntax error or a key given twice
    in one mapping is an :class:`InputError` naming ``source`` (and the key and its lines)."""
    if len(text) > MAX_YAML_CHARS:
        raise InputError(f"the YAML document has {len(text):,} characters, more than loosefit reads "
                         f"({MAX_YAML_CHARS:,}: loosefit.config.MAX_YAML_CHARS)", source)
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader derives from SafeLoader
    except _TooLarge as e:
        raise InputError(f"YAML document refused: {e}", source) from None
    except RecursionError:
        raise InputError(f"YAML document refused: nested too deeply to read (limit {MAX_YAML_DEPTH} levels)",
                         source) from None
    except _DuplicateKey as e:
        raise InputError(f"{e}: a key may appear once in a mapping (YAML would keep only the last value)",
                         source) from None
    except yaml.YAMLError as e:
        raise InputError(f"invalid YAML: {e}", source) from None


def read_yaml_text(path: str | Path, what: str) -> str:
    """The text of the YAML file ``path`` (``what`` it is, for errors), of which no more than
    :data:`MAX_YAML_CHARS` characters are read: a longer one is refused."""
    path = Path(path)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read(MAX_YAML_CHARS + 1)
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read {what}: {getattr(e, 'strerror', None) or e}", path) from None
    if len(text) > MAX_YAML_CHARS:
        raise InputError(f"the {what} file is longer than loosefit reads ({MAX_YAML_CHARS:,} characters: "
                         "loosefit.config.MAX_YAML_CHARS)", path)
    return text


class _Mismatch(Exception):
    """A value does not fit a field; carries the dotted key and the problem (turned into InputError)."""

    def __init__(self, key: str, problem: str):
        self.key = key
        self.problem = problem
        super().__init__(f"{key}: {problem}" if key else problem)


_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxstring, _SHORT.maxother = 3, 60, 60
_SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxdict = _SHORT.maxset = 4


def _describe(value: Any) -> str:
    text = _SHORT.repr(value)  # bounded: never the whole of a large (or shared, alias-built) value
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(value).__name__} {text}"


def _join(key: str, name: str) -> str:
    return f"{key}.{name}" if key else name


def _type_name(tp: Any) -> str:
    return tp.__name__ if isinstance(tp, type) else str(tp).replace("typing.", "")


def _convert(value: Any, tp: Any, key: str) -> Any:
    """``value`` (from YAML or a default) checked against annotation ``tp`` and converted to it."""
    if tp is Any:
        return value
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin is typing.Union or origin is types.UnionType:
        if value is None:
            if type(None) in args:
                return None
            raise _Mismatch(key, f"must not be null (expected {_type_name(tp)})")
        arms = [arm for arm in args if arm is not type(None)]
        if len(arms) == 1:  # Optional[X]: X's own error is the clearest
            return _convert(value, arms[0], key)
        for arm in arms:
            try:
                return _convert(value, arm, key)
            except _Mismatch:
                continue
        raise _Mismatch(key, f"expected {_type_name(tp)}, got {_describe(value)}")
    if origin is typing.Literal:
        # bool == int in Python: compare types too so that `true` does not match `1`
        if any(value == option and type(value) is type(option) for option in args):
            return value
        raise _Mismatch(key, f"must be one of {list(args)}, got {_describe(value)}")
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, dict):
            raise _Mismatch(key, f"expected a mapping of {tp.__name__} fields, got {_describe(value)}")
        return _build(tp, value, key)
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise _Mismatch(key, f"expected true or false, got {_describe(value)}")
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise _Mismatch(key, f"expected an integer, got {_describe(value)}")
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise _Mismatch(key, f"expected a number, got {_describe(value)}")
    if tp is str:
        if isinstance(value, str):
            return value
        raise _Mismatch(key, f"expected a string, got {_describe(value)} (quote it in YAML)")
    if tp is Path:
        if isinstance(value, (str, Path)):
            return Path(value)
        raise _Mismatch(key, f"expected a path string, got {_describe(value)}")
    if tp in (list, tuple, dict):
        origin, args = tp, ()
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise _Mismatch(key, f"expected a list, got {_describe(value)}")
        if origin is tuple and args and not (len(args) == 2 and args[1] is Ellipsis):
            if len(value) != len(args):
                raise _Mismatch(key, f"expected a list of {len(args)} items, got {len(value)}")
            return tuple(_convert(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
        item_type = args[0] if args else Any
        items = [_convert(v, item_type, f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, dict):
            raise _Mismatch(key, f"expected a mapping, got {_describe(value)}")
        key_type, value_type = args if args else (Any, Any)
        return {
            _convert(k, key_type, f"{key}[{k!r}]"): _convert(v, value_type, _join(key, str(k)))
            for k, v in value.items()
        }
    raise TypeError(f"config field {key!r}: unsupported annotation {tp!r}")


def _init_fields(cls: type) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if f.init]


def _build(cls: type[T], values: dict, key: str) -> T:
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in _init_fields(cls)}
    unknown = [k for k in values if k not in fields]
    if unknown:
        names = ", ".join(repr(_join(key, str(k))) for k in unknown)
        raise _Mismatch("", f"unknown key {names}; {cls.__name__} has {sorted(fields)}")
    kwargs = {}
    for name, f in fields.items():
        if name in values:
            kwargs[name] = _convert(values[name], hints[name], _join(key, name))
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise _Mismatch(_join(key, name), "missing (this key has no default)")
    try:
        return cls(**kwargs)
    except InputError as e:  # a __post_init__ check: say which section it came from
        raise _Mismatch(key, e.problem) from None


def config_from_dict(cls: type[T], values: dict | None, source: str | Path | None = None) -> T:
    """Build dataclass ``cls`` from a (nested) mapping; missing keys keep their defaults.

    Raises :class:`InputError` naming ``source`` (a file, or a description such as an override) and
    the dotted key for unknown keys, missing required keys and values of the wrong type.
    """
    if values is None:
        values = {}
    if not isinstance(values, dict):
        raise InputError(f"a config must be a YAML mapping of {cls.__name__} fields, got {_describe(values)}", source)
    try:
        return _build(cls, values, "")
    except _Mismatch as e:
        raise InputError(f"config key {e.key!r}: {e.problem}" if e.key else f"config: {e.problem}", source) from None


def config_to_dict(cfg: Any) -> Any:
    """A config as plain YAML-ready data: dataclasses become dicts (field order), tuples lists, paths strings."""
    if dataclasses.is_dataclass(cfg) and not isinstance(cfg, type):
        return {f.name: config_to_dict(getattr(cfg, f.name)) for f in _init_fields(type(cfg))}
    if isinstance(cfg, (list, tuple)):
        return [config_to_dict(v) for v in cfg]
    if isinstance(cfg, dict):
        return {k: config_to_dict(v) for k, v in cfg.items()}
    if isinstance(cfg, Path):
        return str(cfg)
    return cfg


def parse_override(text: str) -> tuple[list[str], Any]:
    """``"a.b=1e-3"`` -> ``(["a", "b"], 0.001)``: the dotted key and the value parsed as YAML."""
    key, sep, raw = text.partition("=")
    parts = key.strip().split(".")
    if not sep or not all(p.strip() for p in parts):
        raise InputError(f"bad override {text!r}: expected KEY=VALUE with KEY like 'lr' or 'stages.low.epochs'")
    return [p.strip() for p in parts], load_yaml(raw, f"override {text!r}")


def _merge(base: Any, keys: list[str], value: Any) -> dict:
    """A copy of mapping ``base`` with ``value`` set at ``keys`` (intermediate mappings created)."""
    out = dict(base) if isinstance(base, dict) else {}
    head, rest = keys[0], keys[1:]
    out[head] = _merge(out.get(head), rest, value) if rest else value
    return out


def apply_overrides(cfg: T, overrides: Iterable[str] = ()) -> T:
    """A copy of ``cfg`` with ``"a.b=value"`` overrides applied in order, each type-checked."""
    if isinstance(overrides, str):
        overrides = [overrides]
    cls = type(cfg)
    for text in overrides:
        keys, value = parse_override(text)
        cfg = config_from_dict(cls, _merge(config_to_dict(cfg), keys, value), f"override {text!r}")
    return cfg


def load_config(cls: type[T], path: str | Path | None = None, overrides: Iterable[str] = ()) -> T:
    """Load dataclass ``cls`` from YAML file ``path`` (defaults when ``None``), then apply ``overrides``.

    Args:
        cls: the config dataclass.
        path: a YAML mapping of field names; nested dataclasses and dict fields are nested mappings.
        overrides: ``"key.sub=value"`` strings, applied after the file.

    Raises:
        InputError: unreadable or invalid file, unknown key, wrong type, bad override; the message
            names the file (or the override) and the dotted key.
    """
    values: Any = None
    if path is not None:
        path = Path(path)
        values = load_yaml(read_yaml_text(path, "config"), path)
    return apply_overrides(config_from_dict(cls, values, path), overrides)


def save_config(path: str | Path, cfg: Any) -> Path:
    """Write ``cfg`` (a dataclass) as YAML atomically; :func:`load_config` reads it back equal."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(yaml.safe_dump(config_to_dict(cfg), sort_keys=False, default_flow_style=False))
    return path
