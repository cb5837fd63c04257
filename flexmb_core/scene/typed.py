"""The typed reader: a YAML mapping → a schema dataclass, read from the dataclass's own fields.

Modelled on Drake's ``yaml_load_typed`` (``pydrake.common.yaml``): the schema is the dataclass.
The keys a mapping may hold are the dataclass's fields (a field's ``key`` renames it, e.g.
``from`` for ``Member.start``); the types come from the annotations (``float``, ``int``, ``str``,
``bool``, ``Literal[...]`` choices, fixed tuples such as ``Vec3``, ``tuple[X, ...]``,
``dict[str, X]``, nested dataclasses, ``X | None``); the defaults are the field defaults, and a
field without one (and not optional) is a required key. What an annotation cannot say — unit,
range, a name that must be defined elsewhere in the scene — is the field's metadata, written by
:func:`spec` next to the field in :mod:`flexmb_core.scene.schema`. So a new field is a new key
with its checks, and no list of keys or defaults is kept anywhere else.

Where the YAML form of a value differs from the dataclass the compiler reads (a section's keys
depend on its ``shape``), the schema declares the form: a :class:`OneOf` (Drake: a
``std::variant``; here the tag is a key such as ``kind``) chooses one dataclass per case, and a
form class's ``build()`` returns the schema value. A form is found on the field (``spec(form=…)``)
or on the type (a ``yaml_form`` class attribute). Invariants between the keys of one mapping are
the dataclass's ``check()`` method, raising :class:`Invalid`; what needs other parts of the scene
(does this node exist, is it an end of that member) stays in the loader.

Every error is a :class:`~flexmb_core.errors.SceneError` naming ``file:key``, a bounded excerpt of
the value and what was expected (:class:`~flexmb_core.scene.reader.Node`'s messages).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from dataclasses import MISSING, dataclass
from typing import Any, Callable, Literal, Mapping, Union

from ..errors import excerpt, name_list
from .reader import Node


@dataclass(frozen=True)
class Spec:
    """What a field's annotation cannot say (all optional).

    ``key``: the YAML key when it is not the field's name. ``unit``: for messages (SI).
    ``positive``, ``nonneg``, ``lo``, ``hi``: bounds of a number (or of each integer).
    ``nonzero``: a vector must not be all zeros. ``min_len``: a list of numbers has at least this
    many. ``ref``: the value names something defined elsewhere (``node``, ``member``, …): the
    reader's ``refs[ref]`` is the table of names, or a function of the :class:`Node` that reads it.
    ``in_place``: a mapping given instead of the name is read by ``refs[in_place]`` (a function
    of the :class:`Node` returning the name it registers: a mesh point given by coordinates).
    ``form``: the dataclass or :class:`OneOf` the YAML is read as (for a ``dict`` or a
    ``tuple[X, ...]``: each item's). ``expected``/``hint``: the message for a value of the wrong
    type or out of range, ``expected {expected}, got {value} {hint}``. ``default_from``: the
    default computed from the values read so far (a mapping field name → value). ``when``:
    ``((field, values), …)``: the key applies only while each earlier field has one of those
    values. ``inline``: a nested dataclass whose keys sit in this mapping. ``empty``: a string may
    be empty. ``yaml``: False for a field that is no key (the loader fills it). ``deferred``: a key
    of this mapping that the loader reads itself (it needs the rest of the scene); the field keeps
    its default here. ``doc``: what the key means, added to the message when it is missing.
    """

    key: str | None = None
    unit: str = ""
    positive: bool = False
    nonneg: bool = False
    lo: float | None = None
    hi: float | None = None
    nonzero: bool = False
    min_len: int = 1
    ref: str | None = None
    in_place: str | None = None
    form: Any = None
    expected: str | None = None
    hint: str = ""
    default_from: Callable[[Mapping[str, Any]], Any] | None = None
    when: tuple[tuple[str, tuple[Any, ...]], ...] = ()
    inline: bool = False
    empty: bool = False
    yaml: bool = True
    deferred: bool = False
    doc: str = ""


_NO_SPEC = Spec()


def spec(default: Any = MISSING, *, default_factory: Any = MISSING, **kw: Any) -> Any:
    """A dataclass field with its :class:`Spec`: ``E: float = spec(positive=True, unit="Pa")``,
    ``nu: float = spec(0.0, lo=-0.99, hi=0.4999)``."""
    return dataclasses.field(default=default, default_factory=default_factory, metadata={"yaml": Spec(**kw)})


class Invalid(Exception):
    """Raised by a schema dataclass's ``check()``: ``message`` about ``key`` (None: the mapping)."""

    def __init__(self, message: str, key: str | None = None):
        super().__init__(message)
        self.message = message
        self.key = key


@dataclass(frozen=True, eq=False)          # compared and hashed by identity: one object per form
class OneOf:
    """A mapping whose ``tag`` key chooses the dataclass that reads the rest (``cases``: tag value →
    dataclass). ``title`` names a case in messages (``"a '{}' signal"``): ``key(s) [...] do not
    apply to a 'ramp' signal; expected [...]``, ``a 'ramp' signal needs ['duration']``.
    ``shorthand`` = (case, field): a value that is no mapping is that case's field (a number for a
    constant signal). A case that has a field named ``tag`` is given the tag's value. ``split`` =
    (key, other): a mapping that holds ``key`` is read by the ``other`` form instead (a support on a
    shell ``edge`` rather than on a ``node``)."""

    tag: str
    cases: Mapping[str, type]
    title: str
    shorthand: tuple[str, str] | None = None
    split: tuple[str, OneOf] | None = None


# -- the dataclass side: keys, required keys, defaults --------------------------------------------

@dataclass(frozen=True)
class _Field:
    name: str
    key: str
    tp: Any
    spec: Spec
    default: Any          # MISSING when the dataclass has none (or a default_factory)
    factory: Any          # the dataclass's default_factory, else MISSING
    optional: bool        # the annotation admits None

    @property
    def has_default(self) -> bool:
        return self.default is not MISSING or self.factory is not MISSING

    def make_default(self) -> Any:
        return self.factory() if self.factory is not MISSING else self.default


@functools.lru_cache(maxsize=None)
def _fields(cls: type) -> tuple[_Field, ...]:
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        s = f.metadata.get("yaml", _NO_SPEC)
        tp = hints[f.name]
        out.append(_Field(f.name, s.key or f.name, tp, s, f.default, f.default_factory, _admits_none(tp)))
    return tuple(out)


def _admits_none(tp: Any) -> bool:
    return _is_union(tp) and type(None) in typing.get_args(tp)


def _is_union(tp: Any) -> bool:
    return typing.get_origin(tp) in (Union, types.UnionType)


def _yaml_fields(cls: type, given: Mapping[str, Any] = {}) -> list[_Field]:
    """The fields of ``cls`` that are keys of its mapping, inline dataclasses' fields included."""
    out = []
    for f in _fields(cls):
        if f.name in given or not f.spec.yaml:
            continue
        out.extend(_yaml_fields(f.tp) if f.spec.inline else [f])
    return out


def keys(cls: type, given: Mapping[str, Any] = {}) -> set[str]:
    """The YAML keys a mapping read as ``cls`` may hold (``given`` fields are no keys)."""
    return {f.key for f in _yaml_fields(cls, given)}


def required_keys(cls: type, given: Mapping[str, Any] = {}) -> set[str]:
    """The keys a mapping read as ``cls`` must hold: fields without a default, not optional."""
    return {f.key for f in _yaml_fields(cls, given) if not f.has_default and not f.optional
            and f.spec.default_from is None and not f.spec.deferred}


def check_keys(node: Node, cls: type, given: Mapping[str, Any] = {}) -> Node:
    """``node`` must be a mapping with only ``cls``'s keys and all its required ones."""
    return node.mapping(keys(cls, given), required_keys(cls, given))


# -- reading ------------------------------------------------------------------------------------

def read(node: Node, tp: Any, refs: Mapping[str, Any] | None = None, **given: Any) -> Any:
    """``node``'s value read as ``tp`` (a schema dataclass, a :class:`OneOf` or an annotation).

    ``refs`` maps a field's ``ref`` to the names it may take (a dict) or to a function reading the
    :class:`Node`; ``given`` sets fields of the dataclass that are no keys of the mapping (a name
    from the enclosing mapping's key, a shell's name)."""
    return _Reader(refs or {}).value(node, tp, _NO_SPEC, given)


def read_key(node: Node, cls: type, name: str, refs: Mapping[str, Any] | None = None) -> Any:
    """The field ``name`` of ``cls`` read from the mapping ``node`` (its default when absent) —
    for the loader, which reads the top-level blocks one by one as their references appear."""
    f = next(f for f in _fields(cls) if f.name == name)
    if node.has(f.key):
        return _Reader(refs or {}).value(node.get(f.key), f.tp, f.spec, {})
    if f.has_default:
        return f.make_default()
    if f.optional:
        return None
    raise node.fail(f"missing required key '{f.key}'")


class _Reader:
    def __init__(self, refs: Mapping[str, Any]):
        self.refs = refs

    def value(self, node: Node, tp: Any, s: Spec, given: Mapping[str, Any]) -> Any:
        if _is_union(tp) and type(None) in typing.get_args(tp):
            rest = [a for a in typing.get_args(tp) if a is not type(None)]
            tp = rest[0] if len(rest) == 1 else Union[tuple(rest)]
        origin, args = typing.get_origin(tp), typing.get_args(tp)
        if origin is dict:
            return {k: self.value(child, args[1], s, {"name": k}) for k, child in node.items()}
        if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
            return self._list(node, args[0], s)
        form = s.form or (getattr(tp, "yaml_form", None) if isinstance(tp, type) else None)
        if form is not None:
            return self._form(node, form, given)
        if s.in_place is not None and isinstance(node.value, dict):
            return self.refs[s.in_place](node)
        if s.ref is not None:
            return self._ref(node, s.ref)
        if origin is tuple:
            return self._fixed(node, args, s)
        if dataclasses.is_dataclass(tp):
            return self._form(node, tp, given)
        if origin is Literal:
            return node.string(args)
        return self._scalar(node, tp, s)

    # -- forms ----------------------------------------------------------------------------
    def _form(self, node: Node, form: Any, given: Mapping[str, Any]) -> Any:
        if isinstance(form, OneOf):
            inst = self._one_of(node, form, given)
        else:
            inst = self._dataclass(node, form, _given(form, given))
        return inst.build() if hasattr(inst, "build") else inst

    def _one_of(self, node: Node, form: OneOf, given: Mapping[str, Any]) -> Any:
        if not isinstance(node.value, dict) and form.shorthand is not None:
            case, short = form.shorthand
            cls = form.cases[case]
            if _is_number_field(cls, short) and (isinstance(node.value, bool) or not isinstance(node.value, (int, float))):
                raise node.fail(f"expected a number or a mapping with '{form.tag}' (one of {list(form.cases)}), "
                                f"got {excerpt(node.value)}")
            return self._dataclass(node, cls, _given(cls, given), short=short)
        union = _union(form, given)
        if form.split is not None and isinstance(node.value, dict) and form.split[0] in node.value:
            key, other = form.split
            clash = sorted(k for k in node.value if k in union and k not in _union(other, given))
            if clash:
                raise node.fail(f"key(s) {name_list(clash)} do not apply with '{key}'; expected "
                                f"{sorted(_union(other, given))}")
            return self._one_of(node, other, given)
        node.mapping(union | ({form.split[0]} if form.split else set()), {form.tag})
        tag = node.get(form.tag).string(tuple(form.cases))
        cls = form.cases[tag]
        sub = _given(cls, given, {form.tag: tag})
        allowed = keys(cls, sub) - {form.tag}
        title = form.title.format(tag)
        extra = sorted(k for k in node.value if k != form.tag and k not in allowed)
        if extra:
            raise node.fail(f"key(s) {name_list(extra)} do not apply to {title}; expected {sorted(allowed)}")
        missing = sorted(required_keys(cls, sub) - set(node.value))
        if missing:
            docs = [f.spec.doc for f in _yaml_fields(cls, sub) if f.key in missing and f.spec.doc]
            raise node.fail(f"{title} needs {missing}" + (f" ({'; '.join(docs)})" if docs else ""))
        return self._dataclass(node, cls, sub, checked=True)

    def _dataclass(self, node: Node, cls: type, given: Mapping[str, Any], *, checked: bool = False,
                   short: str | None = None) -> Any:
        shorthand = short or getattr(cls, "yaml_shorthand", None)
        if shorthand is not None and not isinstance(node.value, dict):
            f = next(f for f in _yaml_fields(cls, given) if f.key == shorthand)
            return self._build(node, cls, given, {**given, f.name: self.value(node, f.tp, f.spec, {})})
        if not checked:
            check_keys(node, cls, given)
        return self._build(node, cls, given, self._values(node, cls, given))

    def _values(self, node: Node, cls: type, given: Mapping[str, Any]) -> dict[str, Any]:
        """The fields of ``cls`` read from the keys present (inline dataclasses built here)."""
        values: dict[str, Any] = {}
        for f in _fields(cls):
            if f.name in given:
                values[f.name] = given[f.name]
            elif f.spec.inline:
                values[f.name] = self._build(node, f.tp, {}, self._values(node, f.tp, {}))
            elif f.spec.yaml and not f.spec.deferred and node.has(f.key):
                self._applies(node, cls, f, values)
                values[f.name] = self.value(node.get(f.key), f.tp, f.spec, {})
        return values

    def _build(self, node: Node, cls: type, given: Mapping[str, Any], values: dict[str, Any]) -> Any:
        """``cls`` from ``values``: defaults computed from the others, optional fields None,
        then the dataclass's own ``check()``."""
        for f in _fields(cls):                  # in declaration order: a default may use earlier ones
            if f.name in values:
                continue
            if f.spec.default_from is not None:
                values[f.name] = f.spec.default_from(values)
            elif f.has_default:
                values[f.name] = f.make_default()
            elif f.optional:
                values[f.name] = None
        inst = cls(**values)
        if hasattr(inst, "check"):
            try:
                inst.check()
            except Invalid as exc:
                raise node.fail(exc.message, exc.key) from None
        return inst

    def _applies(self, node: Node, cls: type, f: _Field, values: Mapping[str, Any]) -> None:
        """A key with ``when`` conditions is refused, with every present key failing the same
        condition, when an earlier field holds none of the values it needs."""
        bad = _failing(f, values, cls)
        if bad is None:
            return
        same = [g.key for g in _fields(cls) if g.spec.when and node.has(g.key) and _failing(g, values, cls) == bad]
        field_name, allowed, actual = bad
        raise node.fail(f"key(s) {name_list(same)} apply to {field_name}: {' or '.join(allowed)} only "
                        f"({field_name} is {excerpt(actual)})", same[0])

    # -- values -----------------------------------------------------------------------------
    def _list(self, node: Node, item: Any, s: Spec) -> tuple:
        if item is float:
            return node.numbers(min_len=s.min_len)
        return tuple(self.value(child, item, s, {}) for child in node.list())

    def _ref(self, node: Node, ref: str) -> Any:
        table = self.refs[ref]
        return table(node) if callable(table) else node.name_in(table, ref)

    def _fixed(self, node: Node, args: tuple, s: Spec) -> tuple:
        n, item = len(args), args[0]
        if item is float:
            if s.expected is not None and not (isinstance(node.value, list) and len(node.value) == n):
                raise node.fail(f"expected {s.expected}, got {excerpt(node.value)}")
            return node.vector(n, nonzero=s.nonzero, unit=s.unit)
        if not isinstance(node.value, list) or len(node.value) != n:
            what = s.expected or f"a list of {n} integers"
            raise node.fail(f"expected {what}, got {excerpt(node.value)}")
        return tuple(self.value(child, item, s, {}) for child in node.list())

    def _scalar(self, node: Node, tp: Any, s: Spec) -> Any:
        if tp is float:
            if s.expected is not None:
                return _number_as(node, s)
            return node.number(positive=s.positive, nonneg=s.nonneg, lo=s.lo, hi=s.hi, unit=s.unit)
        if tp is int:
            return node.integer(lo=s.lo, hi=s.hi)
        if tp is bool:
            return node.boolean()
        if tp is str:
            if s.empty and not isinstance(node.value, str):
                raise node.fail(f"expected a string, got {excerpt(node.value)}")
            return node.value if s.empty else node.string()
        if tp is Any:
            return node.value
        raise TypeError(f"{node.where()}: the schema's type {tp!r} has no YAML reading")


def _union(form: OneOf, given: Mapping[str, Any]) -> set[str]:
    """Every key some case of ``form`` takes, and the tag."""
    return set().union(*(keys(c, given) for c in form.cases.values())) | {form.tag}


def _is_number_field(cls: type, key: str) -> bool:
    return any(f.key == key and f.tp is float for f in _fields(cls))


def _given(cls: type, given: Mapping[str, Any], extra: Mapping[str, Any] = {}) -> dict[str, Any]:
    """The ``given`` values that are fields of ``cls`` (a name, a tag)."""
    names = {f.name for f in _fields(cls)}
    return {k: v for k, v in {**given, **extra}.items() if k in names}


def _failing(f: _Field, values: Mapping[str, Any], cls: type) -> tuple[str, tuple, Any] | None:
    """The first ``when`` condition of ``f`` that the values read so far break, else None."""
    for name, allowed in f.spec.when:
        actual = values[name] if name in values else next(g.make_default() for g in _fields(cls) if g.name == name)
        if actual not in allowed:
            return name, allowed, actual
    return None


def _number_as(node: Node, s: Spec) -> float:
    """A number whose every failure reads ``expected {s.expected}, got {value} {s.hint}``."""
    v = node.value
    ok = not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
    ok = ok and not (s.positive and v <= 0) and not (s.nonneg and v < 0)
    ok = ok and not (s.lo is not None and v < s.lo) and not (s.hi is not None and v > s.hi)
    if not ok:
        raise node.fail(f"expected {s.expected}, got {excerpt(v)}" + (f" {s.hint}" if s.hint else ""))
    return float(v)
