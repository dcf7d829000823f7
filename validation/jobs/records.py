"""Data-only records: a typed value stored as numbers, strings and arrays, read back only as
the type it is declared to be.

A record is one uncompressed ZIP (``ZIP_STORED``: nothing to inflate, so no archive bomb)
holding ``record.json`` and one ``arrays/<n>.npy`` per NumPy array. The JSON is the value
laid out by its declared type (``dumps(value, kind)``): a dataclass is an object of its
fields, a list or tuple a list, a dict an object with string keys, an array
``{"$array": "<n>"}``; where the type says ``object`` (an engine's settings) the JSON's own
numbers, strings, lists and objects, with ``{"$tuple": [...]}`` and ``{"$array": "<n>"}``.
Nothing in a record names a class or a function: ``loads(data, kind)`` builds only the types
``kind`` names, checking every field on the way (an unknown or missing field, a value of the
wrong type, an array of an unexpected dtype or shape, an array whose header disagrees with
its size) and raising ``RecordError`` naming the field. Arrays are written with ``allow_pickle=False`` and
read as raw numbers of a checked dtype: nothing is ever unpickled.
"""

from __future__ import annotations

import dataclasses
import io
import json
import numbers
import re
import types
import typing
import zipfile
from collections.abc import Callable
from functools import cache
from typing import Any

import numpy as np

DOCUMENT = "record.json"
"""The record's JSON member."""

ARRAY_MEMBER = "arrays/{key}.npy"
ARRAY_NAME = re.compile(r"arrays/(\d{1,9})\.npy")
"""Array members, numbered in the order the value holds them."""

ARRAY_KINDS = "biuf"
"""NumPy dtype kinds an array may have (bool, integers, floats): never ``O`` (objects,
pickled), ``V`` (records) or strings."""

ARRAY_MARK = "$array"
TUPLE_MARK = "$tuple"
"""Keys that mark an array or a tuple where the declared type is ``object``."""

Shapes = dict[type, dict[str, tuple]]
"""Per dataclass, per array field: the expected shape, each entry an int or a name; a name
stands for one length shared by the instance's arrays (``samples``), or given by the reader
(``bodies``, ``loads(bindings=...)``)."""


class RecordError(ValueError):
    """A record that is not the value it must be: ``field`` names where (``a.b[2].c``)."""

    def __init__(self, field: str, problem: str):
        super().__init__(f"{field or 'record'}: {problem}")
        self.field = field


def dumps(value: Any, kind: Any) -> bytes:
    """``value`` (of type ``kind``) as the bytes of one record; ``TypeError`` when it is not."""
    arrays: list[np.ndarray] = []
    tree = _encode(value, kind, "", arrays)
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_STORED) as archive:
        archive.writestr(DOCUMENT, json.dumps(tree, separators=(",", ":")))
        for key, array in enumerate(arrays):
            with archive.open(ARRAY_MEMBER.format(key=key), "w") as member:
                np.save(member, array, allow_pickle=False)
    return buffer.getvalue()


def loads(
    source: bytes | typing.BinaryIO,
    kind: Any,
    shapes: Shapes | None = None,
    bindings: dict[str, int] | None = None,
) -> Any:
    """The value of type ``kind`` a record (its bytes, or a seekable binary file) holds;
    ``RecordError`` naming the field that is not as declared. ``shapes``: array shapes per
    dataclass field (``Shapes``), ``bindings`` the lengths the reader knows; an array's shape
    is checked from its header, before its data is read."""
    handle = io.BytesIO(source) if isinstance(source, bytes) else source
    size = handle.seek(0, io.SEEK_END)
    handle.seek(0)
    try:
        archive = zipfile.ZipFile(handle)
    except (zipfile.BadZipFile, OSError, ValueError) as error:
        raise RecordError("", f"not a record archive ({error})") from None
    with archive:
        members = _members(archive, size)
        try:
            tree = json.loads(archive.read(members[DOCUMENT]).decode("utf-8"))
        except (ValueError, RecursionError, zipfile.BadZipFile) as error:
            raise RecordError(DOCUMENT, f"not JSON ({type(error).__name__})") from None
        reader = _Reader(archive, members, shapes or {}, dict(bindings or {}))
        return reader.decode(tree, kind, "")


def _members(archive: zipfile.ZipFile, size: int) -> dict[str, zipfile.ZipInfo]:
    """The archive's members by name, each stored uncompressed and no larger than the
    archive; only the document and numbered arrays."""
    members: dict[str, zipfile.ZipInfo] = {}
    for info in archive.infolist():
        if info.filename != DOCUMENT and not ARRAY_NAME.fullmatch(info.filename):
            raise RecordError(
                info.filename, "unexpected member (expected record.json, arrays/N.npy)"
            )
        if info.compress_type != zipfile.ZIP_STORED or info.file_size != info.compress_size:
            raise RecordError(info.filename, "compressed (records are stored uncompressed)")
        if info.file_size > size or info.filename in members:
            raise RecordError(info.filename, "larger than the record, or listed twice")
        members[info.filename] = info
    if DOCUMENT not in members:
        raise RecordError(DOCUMENT, "missing")
    return members


@cache
def _field_types(kind: type) -> dict[str, Any]:
    """A record dataclass's field types, resolved once per class (``typing.get_type_hints``
    compiles every string annotation again on each call: 2 s a job for a 216-body pile)."""
    return typing.get_type_hints(kind)


# -- writing ---------------------------------------------------------------------------


def _encode(value: Any, kind: Any, field: str, arrays: list[np.ndarray]) -> Any:
    if kind in (Any, object):
        return _encode_free(value, field, arrays)
    if kind is type(None):
        if value is not None:
            raise TypeError(f"{field}: expected None; got {type(value).__name__}")
        return None
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (typing.Union, types.UnionType):
        for member in args:
            if _shallow_match(value, member):
                return _encode(value, member, field, arrays)
        raise TypeError(f"{field}: expected {kind}; got {type(value).__name__}")
    if dataclasses.is_dataclass(kind):
        if not isinstance(value, kind):
            raise TypeError(f"{field}: expected {kind.__name__}; got {type(value).__name__}")
        hints = _field_types(kind)
        return {
            f.name: _encode(getattr(value, f.name), hints[f.name], f"{field}.{f.name}", arrays)
            for f in dataclasses.fields(kind)
        }
    if kind is np.ndarray:
        return _encode_array(value, field, arrays)
    if origin in (list, tuple) or kind in (list, tuple):
        fixed = _fixed_length(kind)
        if not isinstance(value, origin or kind) or fixed not in (None, len(value)):
            raise TypeError(f"{field}: expected {kind}; got {type(value).__name__} {value!r:.40}")
        return [
            _encode(item, _item_kind(kind, i), f"{field}[{i}]", arrays)
            for i, item in enumerate(value)
        ]
    if origin is dict or kind is dict:
        value_kind = args[1] if args else Any
        if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
            raise TypeError(f"{field}: expected a dict with string keys")
        return {k: _encode(v, value_kind, f"{field}[{k!r}]", arrays) for k, v in value.items()}
    return _encode_scalar(value, kind, field)


def _encode_scalar(value: Any, kind: Any, field: str) -> Any:
    if not _shallow_match(value, kind):
        raise TypeError(f"{field}: expected {kind}; got {type(value).__name__}")
    return value.item() if isinstance(value, np.generic) else value


def _encode_array(value: Any, field: str, arrays: list[np.ndarray]) -> dict:
    if not isinstance(value, np.ndarray) or value.dtype.kind not in ARRAY_KINDS:
        raise TypeError(f"{field}: expected a numeric NumPy array")
    arrays.append(value)
    return {ARRAY_MARK: str(len(arrays) - 1)}


def _encode_free(value: Any, field: str, arrays: list[np.ndarray]) -> Any:
    """A value whose type is ``object``: JSON's own kinds, tuples and arrays marked."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return _encode_array(value, field, arrays)
    if isinstance(value, (list, tuple)):
        items = [_encode_free(v, f"{field}[{i}]", arrays) for i, v in enumerate(value)]
        return {TUPLE_MARK: items} if isinstance(value, tuple) else items
    if isinstance(value, dict) and all(isinstance(k, str) and not k.startswith("$") for k in value):
        return {k: _encode_free(v, f"{field}[{k!r}]", arrays) for k, v in value.items()}
    raise TypeError(f"{field}: {type(value).__name__} cannot be stored in a record")


def _shallow_match(value: Any, kind: Any) -> bool:
    """Whether ``value`` is of ``kind`` at its top level (the member of a union to use)."""
    if kind in (Any, object):
        return True
    if kind is type(None):
        return value is None
    origin = typing.get_origin(kind) or kind
    if origin in (typing.Union, types.UnionType):
        return any(_shallow_match(value, member) for member in typing.get_args(kind))
    if kind is float:
        return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
    if kind is int:
        return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
    if kind is bool:
        return isinstance(value, (bool, np.bool_))
    return isinstance(value, origin)


def _fixed_length(kind: Any) -> int | None:
    """The length of a fixed tuple type (``tuple[float, float, float]``); None otherwise."""
    args = typing.get_args(kind)
    if typing.get_origin(kind) is tuple and args and not (len(args) == 2 and args[1] is Ellipsis):
        return len(args)
    return None


def _item_kind(kind: Any, index: int) -> Any:
    """The type of item ``index`` of a list or tuple type (``Any`` when bare)."""
    args = typing.get_args(kind)
    if not args:
        return Any
    if typing.get_origin(kind) is tuple and not (len(args) == 2 and args[1] is Ellipsis):
        return args[index] if index < len(args) else None  # None: past a fixed tuple's end
    return args[0]


# -- reading ---------------------------------------------------------------------------


@dataclasses.dataclass
class _Reader:
    """Decodes a record's JSON tree by its declared type, reading arrays from ``archive``."""

    archive: zipfile.ZipFile
    members: dict[str, zipfile.ZipInfo]
    shapes: Shapes
    bindings: dict[str, int]

    def decode(self, tree: Any, kind: Any, field: str) -> Any:
        if kind in (Any, object):
            return self._free(tree, field)
        if kind is None or kind is type(None):
            if tree is not None:
                raise RecordError(field, f"expected null; got {_kind_of(tree)}")
            return None
        origin, args = typing.get_origin(kind), typing.get_args(kind)
        if origin in (typing.Union, types.UnionType):
            return self._union(tree, args, field)
        if dataclasses.is_dataclass(kind):
            return self._dataclass(tree, kind, field)
        if kind is np.ndarray:
            return self._array(tree, field)
        if origin in (list, tuple) or kind in (list, tuple):
            return self._sequence(tree, kind, field)
        if origin is dict or kind is dict:
            if not isinstance(tree, dict):
                raise RecordError(field, f"expected an object; got {_kind_of(tree)}")
            value_kind = args[1] if args else Any
            return {k: self.decode(v, value_kind, f"{field}[{k!r}]") for k, v in tree.items()}
        return _scalar(tree, kind, field)

    def _union(self, tree: Any, members: tuple, field: str) -> Any:
        problems = []
        for member in members:
            try:
                return self.decode(tree, member, field)
            except RecordError as error:
                problems.append(error)
        deepest = max(problems, key=lambda error: len(error.field))
        if deepest.field != field:
            raise deepest
        raise RecordError(field, f"expected {_describe_union(members)}; got {_kind_of(tree)}")

    def _dataclass(self, tree: Any, kind: type, field: str) -> Any:
        if not isinstance(tree, dict):
            raise RecordError(field, f"expected an object ({kind.__name__}); got {_kind_of(tree)}")
        names = [f.name for f in dataclasses.fields(kind)]
        for key in tree:
            if key not in names:
                raise RecordError(f"{field}.{key}", f"unknown field of {kind.__name__}")
        for name in names:
            if name not in tree:
                raise RecordError(f"{field}.{name}", f"missing (a field of {kind.__name__})")
        hints = _field_types(kind)
        shapes = self.shapes.get(kind, {})
        lengths = dict(self.bindings)  # the instance's own lengths (samples) bound as read
        values = {}
        for name in names:
            where = f"{field}.{name}"
            if hints[name] is np.ndarray and name in shapes:
                values[name] = self._array(tree[name], where, shapes[name], lengths)
            else:
                values[name] = self.decode(tree[name], hints[name], where)
        return kind(**values)

    def _sequence(self, tree: Any, kind: Any, field: str) -> Any:
        if not isinstance(tree, list):
            raise RecordError(field, f"expected a list; got {_kind_of(tree)}")
        fixed = _fixed_length(kind)
        if fixed is not None and len(tree) != fixed:
            raise RecordError(field, f"expected {fixed} items; got {len(tree)}")
        items = [self.decode(v, _item_kind(kind, i), f"{field}[{i}]") for i, v in enumerate(tree)]
        return tuple(items) if (typing.get_origin(kind) or kind) is tuple else items

    def _array(
        self, tree: Any, field: str, shape: tuple | None = None, lengths: dict | None = None
    ) -> np.ndarray:
        """The array ``tree`` refers to; its header checked (dtype, ``shape`` when given,
        its size against the bytes stored) before its data is read."""
        if not (
            isinstance(tree, dict)
            and list(tree) == [ARRAY_MARK]
            and isinstance(tree[ARRAY_MARK], str)
        ):
            raise RecordError(field, f'expected an array reference {{"{ARRAY_MARK}": "N"}}')
        name = ARRAY_MEMBER.format(key=tree[ARRAY_MARK])
        info = self.members.get(name)
        if info is None:
            raise RecordError(field, f"{name}: no such array in the record")
        with self.archive.open(info) as handle:
            try:
                found, fortran, dtype = _array_header(handle)
                stored = info.file_size - handle.tell()
                if int(np.prod(found, dtype=object)) * dtype.itemsize != stored:
                    raise ValueError(f"header says shape {found}, but {stored} bytes are stored")
                if shape is not None:
                    _check_shape(found, shape, {} if lengths is None else lengths)
                array = np.frombuffer(handle.read(stored), dtype=dtype)
            except (ValueError, OSError, zipfile.BadZipFile) as error:
                raise RecordError(field, f"{name}: {error}") from None
        return array.reshape(found, order="F" if fortran else "C").copy()

    def _free(self, tree: Any, field: str) -> Any:
        if isinstance(tree, list):
            return [self._free(v, f"{field}[{i}]") for i, v in enumerate(tree)]
        if isinstance(tree, dict):
            if ARRAY_MARK in tree:
                return self._array(tree, field)
            if TUPLE_MARK in tree:
                if list(tree) != [TUPLE_MARK] or not isinstance(tree[TUPLE_MARK], list):
                    raise RecordError(field, f'expected {{"{TUPLE_MARK}": [...]}}')
                return tuple(self._free(v, f"{field}[{i}]") for i, v in enumerate(tree[TUPLE_MARK]))
            return {k: self._free(v, f"{field}[{k!r}]") for k, v in tree.items()}
        return tree


_HEADER_READERS: dict[tuple[int, int], Callable] = {
    (1, 0): np.lib.format.read_array_header_1_0,
    (2, 0): np.lib.format.read_array_header_2_0,
}
"""npy format version -> its header reader (``np.save`` writes 1.0, or 2.0 for huge headers)."""


SCALAR_CHECKS: dict[Any, Callable[[Any], bool]] = {
    float: lambda v: type(v) in (int, float),
    int: lambda v: type(v) is int,
    bool: lambda v: type(v) is bool,
    str: lambda v: type(v) is str,
}
"""Declared scalar type -> the JSON values it accepts (a float field keeps an int as written:
``0`` and ``0.0`` print differently in a CSV)."""


def _scalar(tree: Any, kind: Any, field: str) -> Any:
    check = SCALAR_CHECKS.get(kind)
    if check is None:
        raise RecordError(field, f"type {kind} cannot be read from a record")
    if not check(tree):
        raise RecordError(field, f"expected {kind.__name__}; got {_kind_of(tree)}")
    return tree


def _kind_of(tree: Any) -> str:
    names = {
        dict: "an object",
        list: "a list",
        str: "a string",
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        type(None): "null",
    }
    return names.get(type(tree), type(tree).__name__)


def _describe_union(members: tuple) -> str:
    return " or ".join(getattr(m, "__name__", str(m)).replace("NoneType", "null") for m in members)


def _array_header(handle: typing.BinaryIO) -> tuple[tuple, bool, np.dtype]:
    """(shape, fortran order, dtype) of an npy stream, the dtype one of ``ARRAY_KINDS``."""
    version = np.lib.format.read_magic(handle)
    read_header = _HEADER_READERS.get(version)
    if read_header is None:
        raise ValueError(f"npy format {version} (expected 1.0 or 2.0)")
    shape, fortran, dtype = read_header(handle)
    if dtype.kind not in ARRAY_KINDS or dtype.fields is not None or dtype.subdtype is not None:
        raise ValueError(f"dtype {dtype} (expected bool, integers or floats)")
    return shape, fortran, dtype


def _check_shape(found: tuple, expected: tuple, lengths: dict[str, int]) -> None:
    """``found`` against ``expected`` (ints, or names bound in ``lengths`` on first use)."""
    fits = len(found) == len(expected)
    for size, want in zip(found, expected, strict=False):
        fits = fits and size == (lengths.setdefault(want, size) if isinstance(want, str) else want)
    if not fits:
        text = ", ".join(str(lengths.get(d, d) if isinstance(d, str) else d) for d in expected)
        raise ValueError(f"expected shape ({text}); got {found}")
