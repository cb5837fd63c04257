"""Strict, bounded YAML for scene files.

On top of ``yaml.SafeLoader``: ``1e9`` is a float (YAML 1.2); a duplicate mapping key is an error
(the last one does not silently win); nesting deeper than :data:`MAX_DEPTH` is refused while the
document is composed (no ``RecursionError``); recursive aliases and documents whose alias expansion
exceeds ``Limits.max_yaml_nodes`` (alias bombs) are refused before any Python value is built;
non-UTF-8 bytes are reported with their line and column. Every error is a :class:`SceneError` whose
``where`` is ``file:line:column``.
"""

from __future__ import annotations

import re
from typing import Any

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.parser import Parser
from yaml.reader import Reader
from yaml.resolver import Resolver
from yaml.scanner import Scanner

from ..errors import SceneError, excerpt, thousands
from .limits import DEFAULT_LIMITS, Limits, over_limit

MAX_DEPTH = 64          # a scene nests about 8 levels (members.leg.actuator.command.values[i])
_DEEP = f"nesting deeper than {MAX_DEPTH} levels (a scene needs about 8); check for unbalanced brackets"


class _Refused(Exception):
    """Raised inside the loader; converted to a SceneError with the file name by :func:`parse`."""

    def __init__(self, mark, message: str):
        self.mark = mark
        self.message = message


class _TooMany(Exception):
    def __init__(self, mark, count: int):
        self.mark = mark
        self.count = count


try:                                  # libyaml scans and parses ~5× faster; composing stays in Python
    from yaml.cyaml import CParser as _CParser
except ImportError:                   # pragma: no cover - PyYAML built without libyaml
    _CParser = None


_PARSER = (_CParser,) if _CParser is not None else (Reader, Scanner, Parser)


class _Base(Composer, *_PARSER, SafeConstructor, Resolver):
    """Python composer (depth, size and duplicate checks hook into it) over libyaml's events when
    available, else over PyYAML's pure-Python reader, scanner and parser."""

    def __init__(self, stream):
        if _CParser is not None:
            _CParser.__init__(self, stream)
        else:                         # pragma: no cover
            Reader.__init__(self, stream)
            Scanner.__init__(self)
            Parser.__init__(self)
        Composer.__init__(self)
        SafeConstructor.__init__(self)
        Resolver.__init__(self)


class StrictSceneLoader(_Base):
    """Scene YAML: float exponents, duplicate keys refused, nesting depth and value count bounded."""

    def __init__(self, stream, max_nodes: int = DEFAULT_LIMITS.max_yaml_nodes):
        super().__init__(stream)
        self._depth = 0
        self._count = 0
        self.max_nodes = max_nodes
        self.anchor_names: dict[int, str] = {}

    def compose_node(self, parent, index):
        self._depth += 1
        self._count += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _Refused(self.peek_event().start_mark, _DEEP)
            if self._count > self.max_nodes:
                raise _TooMany(self.peek_event().start_mark, self._count)
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        return node

    def construct_yaml_int(self, node):
        """An integer of the YAML 1.2 core schema (the resolver below): decimal, 0o…, 0x…."""
        text = self.construct_scalar(node).replace("_", "")
        sign = -1 if text.startswith("-") else 1
        digits = text.lstrip("+-")
        try:
            if digits.startswith("0o"):
                return sign * int(digits[2:], 8)
            if digits.startswith("0x"):
                return sign * int(digits[2:], 16)
            return sign * int(digits, 10)
        except ValueError:                 # more than 4300 digits (int ↔ str conversion limit)
            raise _Refused(node.start_mark, f"an integer of {thousands(len(node.value))} digits; "
                                            "expected a number a scene can use") from None

    def compose_mapping_node(self, anchor):
        node = super().compose_mapping_node(anchor)
        seen: dict[tuple[str, str], Any] = {}
        for key_node, _ in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = (key_node.tag, key_node.value)
            if key in seen:
                raise _Refused(key_node.start_mark,
                               f"duplicate key {excerpt(key_node.value, 60)} (first at line {seen[key].line + 1}); "
                               "each key may appear once in a mapping")
            seen[key] = key_node.start_mark
        return self._named(node, anchor)

    def compose_sequence_node(self, anchor):
        return self._named(super().compose_sequence_node(anchor), anchor)

    def _named(self, node, anchor):
        if anchor is not None:                       # kept for messages (self.anchors is cleared)
            self.anchor_names[id(node)] = anchor
        return node


# YAML 1.2 core schema numbers instead of YAML 1.1's: PyYAML's resolvers read `1:2:3` as the
# base-60 integer 3723 and `1:20.5` as 4820.5, and its constructor `017` as octal 15 — a scene
# value or an --override / --param VALUE would silently become another number. Here an integer is
# decimal, 0o octal or 0x hexadecimal (underscores allowed as digit separators), anything else
# that is not a float below is a string, and the schema says what it expected instead.
_INT, _FLOAT = "tag:yaml.org,2002:int", "tag:yaml.org,2002:float"
StrictSceneLoader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag not in (_INT, _FLOAT)]
    for first, resolvers in StrictSceneLoader.yaml_implicit_resolvers.items()}
StrictSceneLoader.add_implicit_resolver(
    _INT, re.compile(r"^(?:[-+]?[0-9][0-9_]*|0o[0-7_]+|0x[0-9a-fA-F_]+)$"), list("-+0123456789"))
StrictSceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                |[-+]?\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                |[-+]?\.(?:inf|Inf|INF)
                |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


StrictSceneLoader.add_constructor("tag:yaml.org,2002:int", StrictSceneLoader.construct_yaml_int)


def expanded_size(root: yaml.Node, limit: int) -> tuple[int, yaml.Node | None, str]:
    """Number of YAML values ``root`` stands for once every alias is expanded, counted without
    expanding (shared nodes are counted once per use, in time linear in the distinct nodes).

    Returns ``(size, node, problem)``: ``node`` is the first node whose expansion exceeds ``limit``
    or that contains itself (``problem`` ``'limit'`` or ``'recursive'``), else None.
    """
    size: dict[int, int] = {}
    active: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            active.discard(key)
            if isinstance(node, yaml.ScalarNode):
                n = 1
            elif isinstance(node, yaml.SequenceNode):
                n = 1 + sum(size[id(c)] for c in node.value)
            else:
                n = 1 + sum(size[id(k)] + size[id(v)] for k, v in node.value)
            size[key] = min(n, limit + 1)
            if n > limit:
                return n, node, "limit"
            continue
        if key in size:
            continue
        if key in active:
            return 0, node, "recursive"
        active.add(key)
        stack.append((node, True))
        children = (node.value if isinstance(node, yaml.SequenceNode)
                    else [c for kv in node.value for c in kv] if isinstance(node, yaml.MappingNode) else [])
        for c in children:
            if id(c) in active:
                return 0, c, "recursive"
            if id(c) not in size:
                stack.append((c, False))
    return size[id(root)], None, ""


def decode(data: bytes, source: str) -> str:
    """UTF-8 text of a scene file, or a SceneError at the line and column of the first bad byte."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        bad = data[exc.start:exc.start + 4]
        raise SceneError(f"{source}:{line}:{col}", f"not UTF-8 text: byte {bad[:1].hex(' ')} at offset "
                                                   f"{thousands(exc.start)} ({excerpt(bad, 30)}); scene files "
                                                   "must be UTF-8 encoded") from None


def parse(text: str, source: str = "<string>", limits: Limits | None = None) -> Any:
    """Parse scene YAML text strictly (see the module docstring)."""
    limits = limits or DEFAULT_LIMITS
    loader = StrictSceneLoader(text, limits.max_yaml_nodes)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        n, bad, problem = expanded_size(node, limits.max_yaml_nodes)
        if problem == "recursive":
            raise _Refused(bad.start_mark, f"recursive alias{_anchor(loader, bad)}: a value contains itself")
        if problem == "limit":
            raise over_limit(_at(source, bad.start_mark), f"YAML values after alias expansion{_anchor(loader, bad)}",
                             n, "max_yaml_nodes", limits, "an alias bomb?" if n > 10 * limits.max_yaml_nodes else "")
        return loader.construct_document(node)
    except _Refused as exc:
        raise SceneError(_at(source, exc.mark), exc.message) from None
    except _TooMany as exc:
        raise over_limit(_at(source, exc.mark), "YAML values (scalars, lists, mappings)", exc.count, "max_yaml_nodes",
                         limits, "counting stopped here") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        if "maximum nesting depth" in (exc.problem or ""):   # libyaml >= 0.2.6 (PyYAML 6.0.4) scans ahead
            raise SceneError(_at(source, mark), _DEEP) from None    # and stops at its own depth of 1000
        what = "; ".join(excerpt(s, 200) for s in (exc.context, exc.problem) if s)
        raise SceneError(_at(source, mark), f"not valid YAML: {what}") from None
    except yaml.reader.ReaderError as exc:    # a control character: PyYAML's reader gives an offset only
        line = text.count("\n", 0, exc.position) + 1
        col = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        raise SceneError(f"{source}:{line}:{col}", f"not valid YAML: the control character "
                                                   f"U+{exc.character:04X} is not allowed in YAML text") from None
    except yaml.YAMLError as exc:
        raise SceneError(source, f"not valid YAML: {excerpt(str(exc), 200)}") from None
    finally:
        loader.dispose()


def _at(source: str, mark) -> str:
    return f"{source}:{mark.line + 1}:{mark.column + 1}" if mark is not None else source


def _anchor(loader: StrictSceneLoader, node) -> str:
    name = loader.anchor_names.get(id(node))
    return f" (anchor &{excerpt(name, 40)[1:-1]})" if name else ""
