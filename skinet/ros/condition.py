"""Conditions on the fields of a ROS 2 message, as a binding writes them (docs/semantics.md §9).

``percentage < 0.2``, ``error_code == FAILED_TO_CHARGE``,
``power_supply_status != POWER_SUPPLY_STATUS_CHARGING and present``: comparisons
(``== != < <= > >=``) of field paths (``header.frame_id``), numbers, ``'strings'``,
``true``/``false`` and the message's constants, joined by ``and``, ``or``, ``not``
and parentheses (grammar: ``condition.lark``); a boolean field alone is a
condition too.  :func:`parse_condition` checks every path and constant against the
message type (an unknown name is an error listing close names) and that both sides
of a comparison are of one kind (number, text, boolean), then compiles the
condition into nested closures over the plain dicts of
:func:`skinet.ros.typestore.to_plain`.

Errors point into the file that holds the condition: ``at`` is the position of its
first character there.  Cost: parsing linear in the text; evaluation one dict
lookup per path element and one comparison per atom.

:func:`unique_message` goes the other way, for a commanded topic resource (the pilot
publishes the state it commands, docs/robot.md): the fields a condition pins to one
value each (``mode == 3``, ``data``, ``not data``, joined by ``and``), or None when
it leaves a choice (``or``, ``!=``, ``<``...).  :func:`example_message` finds a message on which
several conditions are each true or false as wanted (a simulated robot's first sample of a bound
topic: the model's initial states, no event firing).

Examples:
    >>> from skinet.ros.definitions import build_store
    >>> c = parse_condition("percentage < 0.2 and present", "sensor_msgs/msg/BatteryState", build_store())
    >>> c.holds({"percentage": 0.1, "present": True}), c.holds({"percentage": 0.5, "present": True})
    (True, False)
"""

from __future__ import annotations

import copy
import operator
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from itertools import islice, product
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lark import Lark, Token, Tree
from lark.exceptions import UnexpectedInput

from skinet.closenames import unknown
from skinet.errors import Pos, SourceError
from skinet.lang.larkcache import cached_lark
from skinet.lang.larkerrors import check_nesting, check_size, syntax_error
from skinet.ros.typestore import default_instance, to_plain

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

MAX_CONDITION_CHARS = 4096
NUMBERS = frozenset({"int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float32",
                     "float64", "byte", "char", "octet"})
_COMPARE: dict[str, Callable[[Any, Any], bool]] = {
    "==": operator.eq, "!=": operator.ne, "<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge,
}
_OPERATORS = frozenset({"or_", "and_", "not_"})

Plain = Mapping[str, Any]
Getter = Callable[[Plain], Any]


@cache
def _lark() -> Lark:
    return cached_lark(Path(__file__).with_name("condition.lark"), parser="lalr", propagate_positions=True,
                       maybe_placeholders=False)


@dataclass(frozen=True)
class Condition:
    """A compiled condition on messages of ``typename``."""

    text: str
    typename: str
    fields: tuple[str, ...]  # the field paths it reads, for messages showing what it saw
    _test: Callable[[Plain], bool] = field(repr=False, compare=False)

    def holds(self, msg: Plain) -> bool:
        """Whether the condition holds on a message (plain dicts); a missing field raises ``KeyError``."""
        return self._test(msg)

    def shown(self, msg: Plain) -> str:
        """The values the condition reads in ``msg``: ``percentage=0.15, present=True``."""
        from rosbags.typesys.base import normalize_fieldname

        out = []
        for path in self.fields:
            try:
                value: Any = msg
                for part in path.split("."):
                    value = value[normalize_fieldname(part)]
            except (KeyError, TypeError):
                value = "?"
            out.append(f"{path}={value!r}" if isinstance(value, str) and value != "?" else f"{path}={value}")
        return ", ".join(out)


@dataclass(frozen=True)
class _Operand:
    kind: str  # "number", "text", "bool"
    get: Getter
    path: str = ""  # a field path, else ''
    owner: str = ""  # the type holding the field (constants are looked up there first)


class _Compiler:
    def __init__(self, typename: str, store: Typestore, source: str, at: Pos, text: str):
        self.typename = typename
        self.store = store
        self.source = source
        self.at = at
        self.text = text
        self.paths: list[str] = []

    def error(self, node: Tree | Token, message: str) -> SourceError:
        column = node.column if isinstance(node, Token) else node.meta.column
        return SourceError.at(self.source, _shift(self.at, column), message)

    def build(self, node: Tree) -> Callable[[Plain], bool]:
        kind = node.data
        if kind == "or_":
            a, b = (self.build(c) for c in node.children)
            return lambda m: a(m) or b(m)
        if kind == "and_":
            a, b = (self.build(c) for c in node.children)
            return lambda m: a(m) and b(m)
        if kind == "not_":
            a = self.build(node.children[0])
            return lambda m: not a(m)
        if kind == "truth":
            inner = node.children[0]
            operand = self.operand(inner, None)
            if operand.kind != "bool":
                what = operand.path or self.text[inner.meta.start_pos:inner.meta.end_pos]
                raise self.error(inner, f"'{what}' is a {operand.kind}, not a condition: compare it (e.g. "
                                        f"{what} == ...)")
            get = operand.get
            return lambda m: bool(get(m))
        left_node, op, right_node = node.children
        left = self.operand(left_node, right_node)
        right = self.operand(right_node, left_node, left)
        if left.kind != right.kind:
            raise self.error(op, f"'{op}' compares a {left.kind} with a {right.kind}")
        if left.kind != "number" and str(op) not in ("==", "!="):
            raise self.error(op, f"'{op}' orders numbers only; {left.kind}s compare with == or !=")
        compare, lget, rget = _COMPARE[str(op)], left.get, right.get
        return lambda m: compare(lget(m), rget(m))

    def operand(self, node: Tree, other: Tree | None, resolved: _Operand | None = None) -> _Operand:
        kind = node.data
        if kind == "number":
            value = float(node.children[0]) if any(c in node.children[0] for c in ".eE") else int(node.children[0])
            return _Operand("number", lambda m: value)
        if kind == "negative":
            text = str(node.children[0])
            value = -(float(text) if any(c in text for c in ".eE") else int(text))
            return _Operand("number", lambda m: value)
        if kind == "string":
            text = str(node.children[0])[1:-1]
            return _Operand("text", lambda m: text)
        if kind in ("true", "false"):
            value = kind == "true"
            return _Operand("bool", lambda m: value)
        return self.path(node, other, resolved)

    def path(self, node: Tree, other: Tree | None, resolved: _Operand | None) -> _Operand:
        from rosbags.interfaces import Nodetype
        from rosbags.typesys.base import normalize_fieldname

        names = [str(t) for t in node.children]
        owners = [resolved.owner] if resolved is not None and resolved.owner else []
        if len(names) == 1:
            for owner in [*owners, self.typename]:
                const = _constant(self.store, owner, names[0])
                if const is not None:
                    kind, value = const
                    return _Operand(kind, lambda m: value)
        current, keys = self.typename, []
        for i, (name, token) in enumerate(zip(names, node.children)):
            consts, fielddefs = self.store.fielddefs[current]
            found = dict(fielddefs).get(name)
            if found is None:
                known = [f for f, _ in fielddefs] + ([c[0] for c in consts] if i == 0 else [])
                raise self.error(token, unknown("field" if i else "field or constant", name, known, f" of {current}"))
            keys.append(normalize_fieldname(name))
            desc = found
            if desc[0] == Nodetype.NAME and i < len(names) - 1:
                current = desc[1]
                continue
            if i < len(names) - 1:
                raise self.error(names_token(node, i + 1), f"'{'.'.join(names[:i + 1])}' has no fields")
            if desc[0] != Nodetype.BASE:
                what = "a message" if desc[0] == Nodetype.NAME else "an array"
                raise self.error(token, f"'{'.'.join(names)}' is {what}; a condition compares single values "
                                        "(numbers, text, booleans)")
            base = desc[1][0]
            kind = "number" if base in NUMBERS else "text" if base == "string" else "bool"
            self.paths.append(".".join(names))
            return _Operand(kind, _getter(keys), ".".join(names), current)
        raise AssertionError("unreachable")


def names_token(node: Tree, i: int) -> Token:
    return node.children[i]  # type: ignore[return-value]


def _getter(keys: list[str]) -> Getter:
    if len(keys) == 1:
        return operator.itemgetter(keys[0])

    def get(m: Plain) -> Any:
        for k in keys:
            m = m[k]
        return m

    return get


def _constant(store: Typestore, typename: str, name: str) -> tuple[str, Any] | None:
    for const, base, value in store.fielddefs[typename][0]:
        if const == name:
            return ("number" if base in NUMBERS else "text" if base == "string" else "bool"), value
    return None


def _shift(at: Pos, column: int) -> Pos:
    return Pos(at.line, at.column + column - 1)


def parse_condition(text: str, typename: str, store: Typestore, source: str = "<condition>",
                    at: Pos = Pos(1, 1)) -> Condition:
    """Compile ``text`` as a condition on messages of ``typename`` (module docstring).

    Raises :class:`SourceError` at ``source``, positions shifted to ``at`` (where the
    condition's first character is in that file).
    """
    if typename not in store.fielddefs:
        raise SourceError.at(source, at, f"unknown message type '{typename}'")
    check_size(text, source, MAX_CONDITION_CHARS)
    if "\n" in text:
        raise SourceError.at(source, at, "a condition is one line")
    try:
        tree = _lark().parse(text)
    except UnexpectedInput as exc:
        error = syntax_error(_lark(), exc, text, source).diagnostics[0]
        raise SourceError.at(source, _shift(at, error.pos.column if error.pos else 1), error.message) from None
    check_nesting(tree, _OPERATORS, source)
    compiler = _Compiler(typename, store, source, at, text)
    test = compiler.build(tree if isinstance(tree, Tree) else Tree("truth", [tree]))
    return Condition(text, typename, tuple(dict.fromkeys(compiler.paths)), test)




def unique_message(condition: Condition, store: Typestore) -> dict[str, Any] | None:
    """The fields (nested dicts for paths) that ``condition`` pins, each to one value; None when it does not
    name a single value for every field it reads (module docstring).

    Examples:
        >>> from skinet.ros.definitions import build_store
        >>> store = build_store()
        >>> unique_message(parse_condition("data", "std_msgs/msg/Bool", store), store)
        {'data': True}
        >>> unique_message(parse_condition("power_supply_status == POWER_SUPPLY_STATUS_FULL and not present",
        ...                                "sensor_msgs/msg/BatteryState", store), store)
        {'power_supply_status': 4, 'present': False}
        >>> unique_message(parse_condition("percentage < 0.2", "sensor_msgs/msg/BatteryState", store), store) is None
        True
    """
    tree = _lark().parse(condition.text)
    pinned: dict[tuple[str, ...], Any] = {}
    todo: list[Any] = [tree]
    while todo:
        node = todo.pop(0)
        if not isinstance(node, Tree):
            node = Tree("truth", [node])
        if node.data == "and_":
            todo[:0] = node.children
            continue
        found = _pin(node, condition.typename, store)
        if found is None or pinned.get(found[0], found[1]) != found[1]:
            return None
        pinned[found[0]] = found[1]
    out: dict[str, Any] = {}
    for path, value in pinned.items():
        inner = out
        for name in path[:-1]:
            inner = inner.setdefault(name, {})
        inner[path[-1]] = value
    return out


UNSIGNED = frozenset({"uint8", "uint16", "uint32", "uint64", "byte", "char", "octet"})
EXAMPLE_TRIES = 4096  # messages example_message tries at most


def example_message(wanted: Sequence[tuple[Condition, bool]], store: Typestore) -> dict[str, Any] | None:
    """Fields (nested dicts for paths) of a message on which every condition of ``wanted`` (all on one
    message type) has the truth wanted with it; None when none is found.

    The values tried for a field are its default, then each value a condition compares it with and a
    step either side of it (1 for integers, half the value for reals), every boolean for a boolean
    field; the combinations are tried in that order, at most :data:`EXAMPLE_TRIES` of them.  Complete
    for comparisons of fields with literals and constants; a condition relating two fields may find
    none.  Cost: the number of combinations tried times the size of the conditions.

    Examples:
        >>> from skinet.ros.definitions import build_store
        >>> store = build_store()
        >>> ok = parse_condition("percentage >= 0.2", "sensor_msgs/msg/BatteryState", store)
        >>> charging = parse_condition("power_supply_status == POWER_SUPPLY_STATUS_CHARGING",
        ...                            "sensor_msgs/msg/BatteryState", store)
        >>> example_message([(ok, True), (charging, True)], store)
        {'percentage': 0.2, 'power_supply_status': 1}
        >>> example_message([(ok, True), (ok, False)], store) is None
        True
    """
    if not wanted:
        return {}
    typename = wanted[0][0].typename
    values: dict[tuple[str, ...], list[Any]] = {}
    for condition, _ in wanted:
        tree = _lark().parse(condition.text)
        for node in (tree.iter_subtrees_topdown() if isinstance(tree, Tree) else ()):
            if node.data == "path" and _is_path(node, typename, store):
                _candidates(values, node, None, typename, store)
            elif node.data == "compare":
                left, _, right = node.children
                for path, other in ((left, right), (right, left)):
                    if _is_path(path, typename, store):
                        _candidates(values, path, other, typename, store)
    from rosbags.typesys.base import normalize_fieldname

    default = to_plain(default_instance(store, typename))
    for path, tried in values.items():  # the field's own default first
        first = default
        for name in path:
            first = first[normalize_fieldname(name)]
        values[path] = [first, *(x for x in tried if x != first)]
    paths = list(values)
    for combination in islice(product(*(values[p] for p in paths)), EXAMPLE_TRIES):
        fields: dict[str, Any] = {}
        plain = copy.deepcopy(default)
        for path, value in zip(paths, combination):
            inner, seen = fields, plain
            for name in path[:-1]:
                inner, seen = inner.setdefault(name, {}), seen[normalize_fieldname(name)]
            inner[path[-1]] = seen[normalize_fieldname(path[-1])] = value
        if all(condition.holds(plain) == truth for condition, truth in wanted):
            return fields
    return None


def _candidates(values: dict[tuple[str, ...], list[Any]], path: Tree, other: Any, typename: str,
                store: Typestore) -> None:
    """Add the values :func:`example_message` tries for the field at ``path`` compared with ``other``."""
    names = tuple(str(t) for t in path.children)
    found = _field(store, typename, names)
    if found is None:
        return
    owner, base = found
    seen = values.setdefault(names, [])
    if base == "bool":
        more: list[Any] = [False, True]
    elif other is None:
        return
    else:
        literal = _value(other, owner, store) or _value(other, typename, store)
        if literal is None:
            return
        v = literal[0]
        if base == "string":
            more = [v, f"{v}_"]
        elif base in NUMBERS and isinstance(v, (int, float)) and not isinstance(v, bool):
            real = base.startswith("float")
            step = (abs(v) / 2 or 0.5) if real else 1
            more = [v, v + step, v - step]
            more = [float(x) if real else int(x) for x in more if not (base in UNSIGNED and x < 0)]
        else:
            return
    seen += [x for x in more if x not in seen]


def _field(store: Typestore, typename: str, names: tuple[str, ...]) -> tuple[str, str] | None:
    """(the type holding the field, its base type) of a path of single values; None otherwise."""
    from rosbags.interfaces import Nodetype

    current = typename
    for i, name in enumerate(names):
        desc = dict(store.fielddefs[current][1]).get(name)
        if desc is None:
            return None
        if desc[0] == Nodetype.NAME and i < len(names) - 1:
            current = desc[1]
            continue
        if i < len(names) - 1 or desc[0] != Nodetype.BASE:
            return None
        return current, desc[1][0]
    return None


def _pin(node: Tree, typename: str, store: Typestore) -> tuple[tuple[str, ...], Any] | None:
    """(field path, value) of ``path``, ``not path`` or ``path == value`` (either side); None otherwise."""
    if node.data == "not_":
        inner = node.children[0]
        if isinstance(inner, Tree) and inner.data == "truth" and _is_path(inner.children[0], typename, store):
            return tuple(str(t) for t in inner.children[0].children), False
        if isinstance(inner, Tree) and inner.data == "path" and _is_path(inner, typename, store):
            return tuple(str(t) for t in inner.children), False
        return None
    if node.data == "truth" and _is_path(node.children[0], typename, store):
        return tuple(str(t) for t in node.children[0].children), True
    if node.data == "path" and _is_path(node, typename, store):
        return tuple(str(t) for t in node.children), True
    if node.data != "compare" or str(node.children[1]) != "==":
        return None
    left, _, right = node.children
    for path, other in ((left, right), (right, left)):
        if _is_path(path, typename, store):
            value = _value(other, typename, store)
            return None if value is None else (tuple(str(t) for t in path.children), value[0])
    return None


def _is_path(node: Any, typename: str, store: Typestore) -> bool:
    """Whether ``node`` is a field path (not a lone constant of the message)."""
    return isinstance(node, Tree) and node.data == "path" and not (
        len(node.children) == 1 and _constant(store, typename, str(node.children[0])) is not None)


def _value(node: Any, typename: str, store: Typestore) -> tuple[Any] | None:
    """The literal or constant value of ``node``, in a 1-tuple; None for a field path."""
    if not isinstance(node, Tree):
        return None
    if node.data in ("number", "negative"):
        text = str(node.children[0])
        number = float(text) if any(c in text for c in ".eE") else int(text)
        return (-number if node.data == "negative" else number,)
    if node.data == "string":
        return (str(node.children[0])[1:-1],)
    if node.data in ("true", "false"):
        return (node.data == "true",)
    if node.data == "path" and len(node.children) == 1:
        const = _constant(store, typename, str(node.children[0]))
        return None if const is None else (const[1],)
    return None


__all__ = ["Condition", "MAX_CONDITION_CHARS", "parse_condition", "unique_message"]
