"""Safe HDF5 storage of frozen values: arrays, scalars, sequences, dicts, dataclasses.

Nothing is pickled. Values are stored with :func:`write_value` and read with :func:`read_value`:

=============================================  =====================================================
value                                          stored as
=============================================  =====================================================
``None``, bool, int, float, complex, str       an attribute of the parent group; its Python type is
(Python or NumPy scalars)                      recorded in the parent's ``vehid_types`` attribute
``numpy.ndarray`` (numeric, bool)              a dataset, bit for bit; optional ``units`` attribute
tuple/list of numbers (nested, rectangular)    a dataset with ``vehid_encoding`` ``tuple``/``list``
tuple/list of str                              a dataset of UTF-8 strings, tagged the same way
any other tuple/list (of dataclasses, ...)     a group of numbered members ``0, 1, ...``
dict whose JSON round trip is exact            a JSON attribute (tag ``json``)
any other dict with str keys                   a group, one member per key (``vehid_encoding`` ``dict``)
object with ``to_hdf5``/``from_hdf5``          a group it writes itself (``vehid_encoding`` ``hdf5``)
object with ``to_dict``/``from_dict``          a group holding the dict as above (``vehid_encoding``
                                               ``dict-codec``): matrices become datasets
dataclass                                      a group with a ``dataclass`` attribute
                                               ``module:QualName``, one member per init field
=============================================  =====================================================

On reading, classes are imported only from the packages listed in
:data:`TRUSTED_PACKAGES`; any other class name is refused with
:class:`~identification.errors.ArchiveError`, and so is writing an instance
of a class that could not be read back.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
from typing import Any, Mapping

import h5py
import numpy as np

from .errors import ArchiveError

__all__ = ["TRUSTED_PACKAGES", "write_value", "read_value", "write_group", "read_group"]

#: Packages whose classes a stored value may name and :func:`read_value` may import.
TRUSTED_PACKAGES = ("identification", "vehicle", "scenarios")

_TYPES = "vehid_types"  # parent attribute: JSON {attribute name: type tag}
_ENCODING = "vehid_encoding"  # how a dataset or group encodes its value
_LENGTH = "vehid_length"  # number of items of a sequence group
_KEYS = "vehid_keys"  # key order of a dict group (JSON list)
_CLASS = "vehid_class"  # module:QualName of a codec group
_UNITS = "vehid_units"  # dataclass group: JSON {field: unit} from field metadata
_DATACLASS = "dataclass"
_RESERVED_PREFIX = "vehid_"

def member_name(name: str, what: str) -> str:
    """``name`` if it can name an HDF5 member (non-empty, no ``/``); else ArchiveError."""
    if not isinstance(name, str) or not name or "/" in name or name in (".", ".."):
        raise ArchiveError(f"{what} name must be a non-empty string without '/'; got {name!r}")
    return name


def _is_number(value: Any) -> bool:
    return isinstance(value, (bool, int, float, complex, np.bool_, np.number)) and not isinstance(value, np.datetime64)


def _number_tree(value: Any, container: type) -> bool:
    """True when ``value`` is nested ``container``s (one type throughout) of numbers."""
    if isinstance(value, container) and type(value) is container:
        return all(_number_tree(item, container) if not _is_number(item) else True for item in value)
    return False


def _scalar_tag(value: Any) -> str | None:
    if value is None:
        return "none"
    if isinstance(value, (bool, np.bool_)):
        return "bool"
    if isinstance(value, (int, np.integer)):
        return "int"
    if isinstance(value, (float, np.floating)):
        return "float"
    if isinstance(value, (complex, np.complexfloating)):
        return "complex"
    if isinstance(value, str):
        return "str"
    return None


def _json_exact(value: Mapping) -> str | None:
    """The JSON text of a dict when decoding it gives an equal dict, else None."""
    if type(value) is not dict:
        return None
    try:
        text = json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        return None
    return text if json.loads(text) == value else None


def _class_path(value: Any) -> str:
    cls = type(value)
    path = f"{cls.__module__}:{cls.__qualname__}"
    if cls.__module__.split(".")[0] not in TRUSTED_PACKAGES or "<locals>" in cls.__qualname__:
        raise ArchiveError(
            f"cannot archive a {path} value: only classes of the packages "
            f"{', '.join(TRUSTED_PACKAGES)} can be read back"
        )
    return path


def _import_class(path: str) -> type:
    """Import ``module:QualName`` from a trusted package, or refuse."""
    module_name, _, qualname = str(path).partition(":")
    if not module_name or not qualname or "<" in qualname:
        raise ArchiveError(f"malformed class name {path!r} in archive")
    if module_name.split(".")[0] not in TRUSTED_PACKAGES:
        raise ArchiveError(
            f"archive names class {path!r} outside the trusted packages "
            f"({', '.join(TRUSTED_PACKAGES)}); refusing to import it"
        )
    try:
        target: Any = importlib.import_module(module_name)
        for part in qualname.split("."):
            target = getattr(target, part)
    except (ImportError, AttributeError):
        raise ArchiveError(f"archive names class {path!r}, which this workbench does not have") from None
    if not isinstance(target, type):
        raise ArchiveError(f"archive names {path!r}, which is not a class")
    return target


def _check_reserved(name: str) -> None:
    if name == _DATACLASS or name.startswith(_RESERVED_PREFIX):
        raise ArchiveError(f"{name!r} is reserved by the archive format and cannot name a value")


def _set_type(group: h5py.Group, name: str, tag: str | None) -> None:
    types = json.loads(group.attrs.get(_TYPES, "{}"))
    if tag is None:
        types.pop(name, None)
    else:
        types[name] = tag
    if types:
        group.attrs[_TYPES] = json.dumps(types, sort_keys=True)
    elif _TYPES in group.attrs:
        del group.attrs[_TYPES]


def _remove(group: h5py.Group, name: str) -> None:
    if name in group:
        del group[name]
    if name in group.attrs:
        del group.attrs[name]
    _set_type(group, name, None)


def write_value(group: h5py.Group, name: str, value: Any, *, units: str | None = None) -> None:
    """Store ``value`` as member ``name`` of ``group``, replacing any member of that name.

    Parameters
    ----------
    group : h5py.Group
    name : str
        Member name: no ``/``, not ``dataclass`` and not starting ``vehid_``.
    value : object
        Any of the supported values (see the module docstring).
    units : str, optional
        The ``units`` attribute of an array or numeric-sequence dataset.

    Raises
    ------
    ArchiveError
        For a value of an unsupported type, or a class outside
        :data:`TRUSTED_PACKAGES`.
    """
    member_name(name, "value")
    _check_reserved(name)
    _remove(group, name)
    _write_member(group, name, value, units)
    if _KEYS in group.attrs:  # a dict group: remember the key order
        keys = json.loads(group.attrs[_KEYS])
        if name not in keys:
            group.attrs[_KEYS] = json.dumps([*keys, name])


def _write_member(group: h5py.Group, name: str, value: Any, units: str | None) -> None:
    tag = _scalar_tag(value)
    if tag is not None:
        if units is not None:
            raise ArchiveError(f"units apply to arrays and sequences only, not to the scalar {name!r}")
        group.attrs[name] = h5py.Empty("f8") if tag == "none" else value
        _set_type(group, name, tag)
        return
    if isinstance(value, dict):
        text = _json_exact(value)
        if text is not None and units is None:
            group.attrs[name] = text
            _set_type(group, name, "json")
            return
    dataset = _write_dataset(group, name, value)
    if dataset is not None:
        if units is not None:
            dataset.attrs["units"] = units
        return
    if units is not None:
        raise ArchiveError(f"units apply to arrays and sequences only, not to {name!r}")
    subgroup = group.create_group(name)
    try:
        write_group(subgroup, value)
    except BaseException:
        del group[name]
        raise


def _write_dataset(group: h5py.Group, name: str, value: Any) -> h5py.Dataset | None:
    """Write arrays and flat/nested sequences of numbers or strings; None for other values."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biufc":
            raise ArchiveError(
                f"cannot archive array {name!r} of dtype {value.dtype}: use numbers, or a tuple of str"
            )
        return group.create_dataset(name, data=value)
    for container in (tuple, list):
        if _number_tree(value, container):
            try:
                array = np.asarray(value) if len(value) else np.zeros(0)
            except ValueError:
                return None  # ragged: stored item by item
            if array.dtype.kind not in "biufc":
                return None
            dataset = group.create_dataset(name, data=array)
            dataset.attrs[_ENCODING] = container.__name__
            return dataset
        if type(value) is container and value and all(isinstance(item, str) for item in value):
            dataset = group.create_dataset(name, data=list(value), dtype=h5py.string_dtype())
            dataset.attrs[_ENCODING] = f"{container.__name__}-of-str"
            return dataset
    return None


def write_group(group: h5py.Group, value: Any) -> None:
    """Write a structured value as the content of an existing, empty group.

    Parameters
    ----------
    group : h5py.Group
        Empty; receives the value's members and its tags.
    value : dataclass, dict, tuple, list, or object with ``to_hdf5``/``to_dict``
        Scalars and arrays cannot fill a group; store them with :func:`write_value`.

    Raises
    ------
    ArchiveError
        For an unsupported value or a class outside :data:`TRUSTED_PACKAGES`.
    """
    if hasattr(value, "to_hdf5") and hasattr(type(value), "from_hdf5"):
        group.attrs[_CLASS] = _class_path(value)
        value.to_hdf5(group)
        group.attrs[_ENCODING] = "hdf5"
        return
    if hasattr(value, "to_dict") and hasattr(type(value), "from_dict"):
        group.attrs[_CLASS] = _class_path(value)
        group.attrs[_ENCODING] = "dict-codec"
        _write_mapping(group, value.to_dict())
        return
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        group.attrs[_DATACLASS] = _class_path(value)
        units = {}
        for item in dataclasses.fields(value):
            if not item.init:
                continue
            write_value(group, item.name, getattr(value, item.name))
            if "unit" in item.metadata:
                units[item.name] = str(item.metadata["unit"])
        if units:
            group.attrs[_UNITS] = json.dumps(units, sort_keys=True)
        return
    if isinstance(value, Mapping):
        group.attrs[_ENCODING] = "dict"
        _write_mapping(group, value)
        return
    if type(value) in (tuple, list):
        group.attrs[_ENCODING] = type(value).__name__
        group.attrs[_LENGTH] = np.int64(len(value))
        for index, item in enumerate(value):
            write_value(group, str(index), item)
        return
    raise ArchiveError(f"cannot archive a value of type {type(value).__module__}.{type(value).__qualname__}")


def _write_mapping(group: h5py.Group, mapping: Mapping) -> None:
    group.attrs[_KEYS] = "[]"
    for key, item in mapping.items():
        if not isinstance(key, str):
            raise ArchiveError(f"only dicts with str keys can be archived; got key {key!r}")
        write_value(group, key, item)


def read_value(group: h5py.Group, name: str) -> Any:
    """Read member ``name`` of ``group`` as :func:`write_value` stored it.

    Returns
    -------
    object
        A value equal to the one written (arrays bit for bit). NumPy scalars
        come back as the matching Python scalars.

    Raises
    ------
    ArchiveError
        When there is no such member, or it names a class outside
        :data:`TRUSTED_PACKAGES`, or it cannot be rebuilt.
    """
    if name in group:
        member = group[name]
        if isinstance(member, h5py.Dataset):
            return _read_dataset(member)
        return read_group(member)
    if name in group.attrs:
        return _read_attribute(group, name)
    raise ArchiveError(f"{group.name} has no member {name!r}")


def _read_attribute(group: h5py.Group, name: str) -> Any:
    tag = json.loads(group.attrs.get(_TYPES, "{}")).get(name)
    raw = group.attrs[name]
    if isinstance(raw, h5py.Empty) or tag == "none":
        return None
    if tag == "json":
        return json.loads(raw)
    converters = {"bool": bool, "int": int, "float": float, "complex": complex, "str": str}
    if tag in converters:
        return converters[tag](raw)
    if isinstance(raw, np.generic):
        return raw.item()
    return raw


def _read_dataset(dataset: h5py.Dataset) -> Any:
    encoding = dataset.attrs.get(_ENCODING)
    if encoding in ("tuple-of-str", "list-of-str"):
        items = [str(item) for item in dataset.asstr()[...]]
        return tuple(items) if encoding == "tuple-of-str" else items
    array = dataset[...]
    if encoding == "list":
        return array.tolist()
    if encoding == "tuple":
        return _tuples(array.tolist())
    return array


def _tuples(value: Any) -> Any:
    return tuple(_tuples(item) for item in value) if isinstance(value, list) else value


def read_group(group: h5py.Group) -> Any:
    """Read a group written by :func:`write_group` (or by :func:`write_value`) back into its value."""
    attrs = group.attrs
    if _DATACLASS in attrs:
        cls = _import_class(attrs[_DATACLASS])
        if not dataclasses.is_dataclass(cls):
            raise ArchiveError(f"{group.name} names {attrs[_DATACLASS]!r}, which is not a dataclass")
        present = set(group.keys()) | set(attrs.keys())
        kwargs = {f.name: read_value(group, f.name) for f in dataclasses.fields(cls) if f.init and f.name in present}
        return _construct(group, cls, lambda: cls(**kwargs))
    encoding = attrs.get(_ENCODING)
    if encoding == "hdf5":
        cls = _import_class(attrs[_CLASS])
        return _construct(group, cls, lambda: cls.from_hdf5(group))
    if encoding == "dict-codec":
        cls = _import_class(attrs[_CLASS])
        mapping = _read_mapping(group)
        return _construct(group, cls, lambda: cls.from_dict(mapping))
    if encoding == "dict":
        return _read_mapping(group)
    if encoding in ("tuple", "list"):
        items = [read_value(group, str(index)) for index in range(int(attrs[_LENGTH]))]
        return tuple(items) if encoding == "tuple" else items
    raise ArchiveError(f"{group.name} is not a value written by the archive serializer")


def _read_mapping(group: h5py.Group) -> dict[str, Any]:
    keys = json.loads(group.attrs.get(_KEYS, "[]"))
    return {key: read_value(group, key) for key in keys}


def _construct(group: h5py.Group, cls: type, build: Any) -> Any:
    try:
        return build()
    except (TypeError, ValueError, KeyError) as exc:
        raise ArchiveError(f"{group.name} does not rebuild a {cls.__qualname__}: {exc}") from None
