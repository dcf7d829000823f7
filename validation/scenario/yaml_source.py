"""Strict YAML reading that remembers where every value came from.

``yaml.safe_load`` semantics with three additions that a scenario format needs:

- every value's position (line, column) is kept, keyed by its field path
  (``("bodies", 1, "shape", "radius")``), so an error can point at the source;
- duplicate keys are errors (PyYAML silently keeps the last one, which would let a
  typo change the physics);
- the document may expand to at most ``MAX_VALUES`` values and nest at most ``MAX_DEPTH``
  deep, and may not refer to itself through an alias (``a: &a [*a]``): all three are judged
  on the composed node graph, each shared node once, before a single value is built, so an
  alias bomb ("billion laughs") is refused in milliseconds instead of being expanded, and
  only the plain YAML tags are accepted (no ``!!python/...`` or custom tags);
- the file is opened without blocking and must be a regular file of at most ``MAX_BYTES``
  (judged from ``fstat`` before a byte is read): a FIFO, a device (``/dev/zero``) or a socket
  named ``*.yaml`` is refused by its type, never read.
"""

from __future__ import annotations

import os
import re
import stat
import sys
from dataclasses import dataclass, field
from pathlib import Path

import yaml

MAX_BYTES = 5_000_000
"""Bytes a scenario file may have; a scene is a page of text, not a data set (a 20,000-body
scene as ``yaml.safe_dump`` writes it, flow or block style, has 2.3 MB)."""

BYTES_PER_VALUE = 5
"""The value cap scales with the file-size cap: one value per 5 bytes. Plain values cannot
expand, and a scene's bodies take 6.3 bytes a value, keys included (the benchmarks/scale.py
grid as ``yaml.safe_dump`` writes it: 1,432,196 bytes, 226,820 values for 12,600 bodies), so
a file of bodies up to ``MAX_BYTES`` is under the cap; only aliases (counted at every use) can
pass it: a billion-laughs bomb has 10⁹ values."""

MAX_VALUES = MAX_BYTES // BYTES_PER_VALUE
"""Values a scenario document may expand to (aliases counted at every use): 1,000,000."""

MAX_DEPTH = 32
"""Nesting a scenario document may have. A scene is at most 5 levels deep
(``known[0].engine`` is 2, ``bodies[0].shape.half_extents[2]`` 4); a document nested deeper is
a mistake or an attack, and building it would exhaust Python's recursion (an alias that
refers to itself nests without end)."""

PLAIN_TAGS = {
    "tag:yaml.org,2002:str",
    "tag:yaml.org,2002:int",
    "tag:yaml.org,2002:float",
    "tag:yaml.org,2002:bool",
    "tag:yaml.org,2002:null",
    "tag:yaml.org,2002:seq",
    "tag:yaml.org,2002:map",
}
"""The only tags a scenario may use: YAML's own scalars and collections."""

Path_ = tuple[str | int, ...]


class _ScenarioLoader(yaml.SafeLoader):
    """SafeLoader that also reads ``1e-3`` and ``2E5`` as floats (YAML 1.2; YAML 1.1, and so
    plain PyYAML, wants a dot in the mantissa and would read them as strings)."""


class _FastScenarioLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """The same rules with libyaml's parser where PyYAML has it: composing the nodes of a
    10,000-body scene (the benchmarks/scale.py grid, 1.1 MB) took 1.9 s instead of 6.1 s in
    pure Python (shared 2-core machine); the resolver, and so every tag, stays PyYAML's."""


for _loader in (_ScenarioLoader, _FastScenarioLoader):
    _loader.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
        list("-+0123456789"),
    )


YAML11_NUMBERS = {
    "binary": re.compile(r"^[-+]?0b[0-1_]+$"),
    "octal": re.compile(r"^[-+]?0[0-7_]+$"),
    "base-60": re.compile(r"^[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+(?:\.[0-9_]*)?$"),
}
"""Number forms of YAML 1.1 that PyYAML reads and YAML 1.2 does not: ``010`` is 8 (1.2: 10),
``1:30`` is 90 (1.2: the text "1:30"), ``0b101`` is 5 (1.2: text). A scene means one number;
a form two readers read differently is refused, never guessed."""

SMALLEST_NORMAL = sys.float_info.min
"""2.2250738585072014e-308, the smallest double of full precision. A non-zero value below it
(subnormal, ``5e-324``) or one that rounds to 0 (``1e-400``) has no physical meaning in a
scene and breaks the arithmetic after it (a mass of 5e-324 has a singular inertia)."""


class YamlSourceError(ValueError):
    """A document that is not acceptable YAML; ``line`` and ``column`` are 1-based or None,
    ``path`` the field path of the value it concerns (empty: the document)."""

    def __init__(
        self,
        message: str,
        line: int | None = None,
        column: int | None = None,
        path: tuple[str | int, ...] = (),
    ):
        super().__init__(message)
        self.message, self.line, self.column, self.path = message, line, column, path


@dataclass
class SourceMap:
    """Where each field path of a document starts in its file (1-based line, column)."""

    marks: dict[Path_, tuple[int, int]] = field(default_factory=dict)

    def locate(self, path: Path_) -> tuple[int, int] | None:
        """The position of ``path``, or of its nearest ancestor that has one."""
        for end in range(len(path), -1, -1):
            mark = self.marks.get(tuple(path[:end]))
            if mark is not None:
                return mark
        return None


def read_yaml(path: Path) -> tuple[object, SourceMap]:
    """The Python value of the YAML file at ``path`` and its source map.

    Raises ``YamlSourceError`` for unreadable files, syntax errors, duplicate keys,
    non-plain tags and documents over the size limits.
    """
    raw = read_bounded(path)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise YamlSourceError(f"not UTF-8 text (byte {error.start})") from None
    try:
        node = yaml.compose(text, Loader=_FastScenarioLoader)
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark
        what = error.problem or "not valid YAML"
        raise YamlSourceError(
            f"not valid YAML: {what}",
            mark.line + 1 if mark else None,
            mark.column + 1 if mark else None,
        ) from None
    except yaml.YAMLError as error:
        raise YamlSourceError(f"not valid YAML: {error}") from None
    source = SourceMap()
    if node is None:
        return None, source
    check_graph(node)
    builder = _Builder(source)
    return builder.build(node, ()), source


FILE_KINDS = {
    stat.S_IFIFO: "a FIFO (named pipe)",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFSOCK: "a socket",
    stat.S_IFDIR: "a folder",
}
"""File types a scenario cannot be, by the name a message gives them."""


def read_bounded(path: Path) -> bytes:
    """The bytes of the regular file at ``path``, at most ``MAX_BYTES``; ``YamlSourceError``
    for anything else, decided from ``fstat`` before reading (O_NONBLOCK: opening a FIFO
    does not wait for a writer)."""
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as error:
        raise YamlSourceError(f"cannot read the file: {error.strerror or error}") from None
    try:
        found = os.fstat(descriptor)
        if not stat.S_ISREG(found.st_mode):
            kind = FILE_KINDS.get(stat.S_IFMT(found.st_mode), "not a regular file")
            raise YamlSourceError(f"expected a regular file; this is {kind}")
        if found.st_size > MAX_BYTES:
            raise YamlSourceError(
                f"the file has {found.st_size} bytes; at most {MAX_BYTES} (MAX_BYTES) are accepted"
            )
        with os.fdopen(os.dup(descriptor), "rb") as handle:
            raw = handle.read(MAX_BYTES + 1)  # a file growing while read stops here too
    except OSError as error:
        raise YamlSourceError(f"cannot read the file: {error.strerror or error}") from None
    finally:
        os.close(descriptor)
    if len(raw) > MAX_BYTES:
        raise YamlSourceError(f"the file has more than {MAX_BYTES} bytes (MAX_BYTES)")
    return raw


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def _refused(message: str, node: yaml.Node) -> YamlSourceError:
    return YamlSourceError(message, node.start_mark.line + 1, node.start_mark.column + 1)


NUMBER_TAGS = {"tag:yaml.org,2002:int", "tag:yaml.org,2002:float"}
"""The tags of the scalars read as numbers (the ones ``YAML11_NUMBERS`` and
``SMALLEST_NORMAL`` judge)."""


def _nonzero(text: str) -> bool:
    """Whether a number's text has a non-zero digit in its mantissa (``1e-400``, not ``0.0``)."""
    mantissa = re.split(r"[eE]", text, maxsplit=1)[0]
    return any(c in "123456789" for c in mantissa)


def check_graph(root: yaml.Node) -> None:
    """Refuse a composed document that refers to itself through an alias, nests deeper than
    ``MAX_DEPTH`` or would expand to more than ``MAX_VALUES`` values (aliases counted at every
    use), judged on the node graph before anything is built: one pass, each shared node
    sized once (a depth-first walk with an explicit stack, so no recursion either)."""
    size: dict[int, int] = {}
    open_nodes: set[int] = set()
    stack: list[tuple[yaml.Node, int, bool]] = [(root, 1, False)]
    while stack:
        node, depth, closing = stack.pop()
        if closing:
            open_nodes.discard(id(node))
            size[id(node)] = 1 + sum(size[id(child)] for child in _children(node))
            if size[id(node)] > MAX_VALUES:
                raise _refused(
                    f"the document expands to more than {MAX_VALUES} values, the cap on a "
                    "scenario's size (MAX_VALUES; aliases count at every use)",
                    node,
                )
            continue
        if id(node) in size:
            continue
        if depth > MAX_DEPTH:
            raise _refused(f"the document nests deeper than {MAX_DEPTH} levels (MAX_DEPTH)", node)
        open_nodes.add(id(node))
        stack.append((node, depth, True))
        for child in _children(node):
            if id(child) in open_nodes:
                raise _refused(
                    "an alias refers to the value that contains it (a document that refers "
                    "to itself has no end); write the value out instead",
                    child,
                )
            stack.append((child, depth + 1, False))


class _Builder:
    """Turns a composed node graph into Python values, counting every value built."""

    def __init__(self, source: SourceMap):
        self.source = source
        self.count = 0
        self.constructor = _ScenarioLoader("")  # only for its scalar resolution rules

    def build(self, node: yaml.Node, path: Path_) -> object:
        self.count += 1
        if self.count > MAX_VALUES:
            raise YamlSourceError(
                f"the document expands to more than {MAX_VALUES} values, the cap on a "
                "scenario's size (MAX_VALUES; aliases count at every use)",
                node.start_mark.line + 1,
                node.start_mark.column + 1,
            )
        self.source.marks.setdefault(path, (node.start_mark.line + 1, node.start_mark.column + 1))
        if node.tag not in PLAIN_TAGS:
            raise YamlSourceError(
                f"the tag {node.tag!r} is not allowed; use plain YAML values",
                node.start_mark.line + 1,
                node.start_mark.column + 1,
            )
        if isinstance(node, yaml.MappingNode):
            return self._mapping(node, path)
        if isinstance(node, yaml.SequenceNode):
            return [self.build(item, (*path, i)) for i, item in enumerate(node.value)]
        return self._scalar(node, path)

    def _scalar(self, node: yaml.ScalarNode, path: Path_) -> object:
        """The value of a plain scalar; a YAML 1.1 number form (``YAML11_NUMBERS``) or a
        number below ``SMALLEST_NORMAL`` is refused at its field."""
        value = self.constructor.construct_object(node, deep=True)
        if node.tag not in NUMBER_TAGS:
            return value
        for form, pattern in YAML11_NUMBERS.items():
            if pattern.match(node.value):
                raise self._refused(
                    f"{node.value} is {value} in YAML 1.1 ({form}) and not that number in "
                    f"YAML 1.2; expected a decimal number: write {value}, or quote text",
                    node,
                    path,
                )
        if 0 < abs(value) < SMALLEST_NORMAL or (value == 0 and _nonzero(node.value)):
            raise self._refused(
                f"{node.value} is below {SMALLEST_NORMAL:.17g}, the smallest normal double "
                "(SMALLEST_NORMAL); expected 0 or a number of at least that size",
                node,
                path,
            )
        return value

    def _refused(self, message: str, node: yaml.Node, path: Path_) -> YamlSourceError:
        """A refusal of the value at ``path``, placed at its field (the key) as every
        field's problem is."""
        line, column = self.source.locate(path) or (
            node.start_mark.line + 1,
            node.start_mark.column + 1,
        )
        return YamlSourceError(message, line, column, path)

    def _mapping(self, node: yaml.MappingNode, path: Path_) -> dict:
        self.constructor.flatten_mapping(node)  # resolves YAML merge keys (<<)
        result: dict = {}
        for key_node, value_node in node.value:
            key = self.build(key_node, (*path, "<key>"))
            if not isinstance(key, str | int | float | bool) and key is not None:
                raise YamlSourceError(
                    "a mapping key must be a plain value",
                    key_node.start_mark.line + 1,
                    key_node.start_mark.column + 1,
                )
            if key in result:
                raise YamlSourceError(
                    f"duplicate key {key!r}",
                    key_node.start_mark.line + 1,
                    key_node.start_mark.column + 1,
                )
            # a field's position is its key's: that is where an editor should point
            key_mark = key_node.start_mark
            self.source.marks[(*path, key)] = (key_mark.line + 1, key_mark.column + 1)
            result[key] = self.build(value_node, (*path, key))
        return result
