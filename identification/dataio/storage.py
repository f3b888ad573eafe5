"""Safe HDF5 storage of frozen values: scalars, arrays, sequences, dicts and registered types.

Nothing is pickled, and no stored value names a Python class. :func:`write_value`
stores a scalar as an attribute (its type in the parent's ``vehid_types``), an
array or a rectangular sequence as a dataset, other sequences and dicts as
groups, and a value of a type registered with :func:`register_codec` as a group
tagged with the type's schema name and version; :func:`read_value` rebuilds
them, and only registered types. The layout is in ``results/RESULTS_LAYOUT.md``
(Values). Archives written before schemas named classes (``module:QualName``):
each type is registered with the fixed name it had then (together the table
:data:`LEGACY_CLASS_PATHS`), and any other name is refused with
:class:`~identification.errors.ArchiveError`.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from typing import Any, Mapping

import h5py
import numpy as np

from ..errors import ArchiveError
from ..frozen import FrozenDict

__all__ = ["LEGACY_CLASS_PATHS", "register_codec", "write_value", "read_value", "write_group", "read_group"]

_TYPES = "vehid_types"  # parent attribute: JSON {attribute name: type tag}
_ENCODING = "vehid_encoding"  # how a dataset or group encodes its value
_LENGTH = "vehid_length"  # number of items of a sequence group
_KEYS = "vehid_keys"  # key order of a dict group (JSON list)
_SCHEMA = "vehid_schema"  # schema name of a registered type's group
_SCHEMA_VERSION = "vehid_schema_version"
_LEGACY_CLASS = "vehid_class"  # module:QualName of a to_dict/to_hdf5 group, before schemas
_UNITS = "vehid_units"  # dataclass group: JSON {field: unit} from field metadata
_LEGACY_DATACLASS = "dataclass"  # module:QualName of a dataclass group, before schemas
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


_SCALAR_TAGS = (((bool, np.bool_), "bool"), ((int, np.integer), "int"), ((float, np.floating), "float"),
                ((complex, np.complexfloating), "complex"), ((str,), "str"))  # bool before int: it is one


def _scalar_tag(value: Any) -> str | None:
    if value is None:
        return "none"
    return next((tag for types, tag in _SCALAR_TAGS if isinstance(value, types)), None)


def _json_exact(value: Mapping) -> str | None:
    """The JSON text of a dict (or a read-only mapping, a frozen result's) when decoding it gives an equal
    dict, else None."""
    if type(value) is not dict and not isinstance(value, FrozenDict):
        return None
    try:
        text = json.dumps(value, allow_nan=False, default=_mapping_as_dict)
    except (TypeError, ValueError):
        return None
    return text if json.loads(text) == value else None


def _mapping_as_dict(value: Any) -> dict:
    """A read-only mapping nested in a dict, as the dict it reads as (nothing else JSON cannot hold)."""
    if isinstance(value, FrozenDict):
        return dict(value)
    raise TypeError(f"{type(value).__name__} is not JSON")


_SCHEMAS: dict[str, tuple[type, int]] = {}  # schema name: (class, version)
_SCHEMA_OF: dict[type, str] = {}

#: The class names (``module:QualName``) archives carried before schemas, and the schema each now reads as.
LEGACY_CLASS_PATHS: dict[str, str] = {}


def register_codec(cls: type, schema: str, version: int = 1, *, legacy_path: str | None = None) -> None:
    """Archive values of ``cls`` under the name ``schema``, which stays as long as such archives exist.

    ``cls`` writes itself (``to_hdf5``/``from_hdf5``), converts to a dict
    (``to_dict``/``from_dict``) or is a dataclass (one member per init field).
    Raise ``version`` whenever the stored layout changes: archives of another
    version are refused. ``legacy_path`` is the class name archives stored
    before schemas, when there are such archives; they read as version 1.
    """
    if not (hasattr(cls, "from_hdf5") or hasattr(cls, "from_dict") or dataclasses.is_dataclass(cls)):
        raise TypeError(f"{cls.__qualname__} has no stored form: give it to_dict/from_dict or make it a dataclass")
    if _SCHEMAS.get(schema, (cls,))[0] is not cls:
        raise ValueError(f"schema {schema!r} already stores {_SCHEMAS[schema][0].__qualname__}")
    _SCHEMAS[schema], _SCHEMA_OF[cls] = (cls, int(version)), schema
    if legacy_path is not None:
        LEGACY_CLASS_PATHS[legacy_path] = schema


@functools.cache
def _register_identification_types() -> None:
    # On first use, not at import: these modules load the numerics, which storing a dict does not need.
    from .. import data
    from ..filtering import iekf, spline_iekf
    from ..assessment import metrics, residuals
    from ..models import modal, modal_structure, scheduled, spline_modal
    from . import preparation
    from ..models.discrete import ContinuousModel, DiscreteModel
    from ..classical.least_squares import ArxModel  # by name: the package's ``least_squares`` is the function
    from ..classical.pencil import PencilModel
    from ..classical.subspace import SubspaceResult
    from ..filtering.greybox_model import IdentifiedGreyBox
    from ..models.responses import TimeResponse

    for cls, schema, legacy_path in (
        (data.IOData, "io_data", "identification.data:IOData"),
        (metrics.FitMetrics, "fit_metrics", "identification.metrics:FitMetrics"),
        (iekf.FilterState, "iekf_filter_state", "identification.iekf:FilterState"),
        (iekf.IEKFOptions, "iekf_options", "identification.iekf:IEKFOptions"),
        (modal.ModalModel, "modal_model", "identification.modal:ModalModel"),
        (modal_structure.ModalStructure, "modal_structure", "identification.modal:ModalStructure"),
        (preparation.Preparation, "preparation", "identification.preparation:Preparation"),
        (preparation.ReadSettings, "read_settings", "identification.preparation:ReadSettings"),
        (preparation.RecordOffsets, "record_offsets", "identification.preparation:RecordOffsets"),
        (residuals.ResidualTests, "residual_tests", "identification.residuals:ResidualTests"),
        (scheduled.ScheduledModalModel, "scheduled_modal_model", "identification.scheduled:ScheduledModalModel"),
        (spline_iekf.SplineIEKFOptions, "spline_iekf_options", "identification.spline_iekf:SplineIEKFOptions"),
        (spline_modal.SplineModalModel, "spline_modal_model", "identification.spline_modal:SplineModalModel"),
        (spline_modal.SplineModalStructure, "spline_modal_structure",
         "identification.spline_modal:SplineModalStructure"),
    ):
        register_codec(cls, schema, legacy_path=legacy_path)
    # every other identified model class: dataclasses, one member per field (never archived before schemas)
    for cls, schema in (
        (DiscreteModel, "discrete_model"),
        (ContinuousModel, "continuous_model"),
        (ArxModel, "arx_model"),
        (PencilModel, "pencil_model"),
        (SubspaceResult, "subspace_model"),
        (IdentifiedGreyBox, "grey_box_model"),
        (TimeResponse, "time_response"),
    ):
        register_codec(cls, schema)


def _check_reserved(name: str) -> None:
    if name == _LEGACY_DATACLASS or name.startswith(_RESERVED_PREFIX):
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
        The open group, written into.
    name : str
        Member name: no ``/``, not ``dataclass`` and not starting ``vehid_``.
    value : object
        Any of the supported values (``results/RESULTS_LAYOUT.md``, Values).
    units : str, optional
        The ``units`` attribute of an array or numeric-sequence dataset.

    Raises
    ------
    ArchiveError
        For a value of an unsupported type, or of a class without a registered schema.
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
    if isinstance(value, (dict, FrozenDict)):
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
            raise ArchiveError(f"cannot archive array {name!r} of dtype {value.dtype}: use numbers, or a tuple of str")
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
    value : registered type, dict, tuple or list
        Scalars and arrays cannot fill a group; store them with :func:`write_value`.

    Raises
    ------
    ArchiveError
        For an unsupported value or a class without a registered schema.
    """
    _register_identification_types()
    if type(value) in _SCHEMA_OF:
        schema = _SCHEMA_OF[type(value)]
        group.attrs[_SCHEMA], group.attrs[_SCHEMA_VERSION] = schema, np.int64(_SCHEMAS[schema][1])
        if hasattr(value, "from_hdf5"):  # the same choice as the reader's
            value.to_hdf5(group)
        elif hasattr(value, "from_dict"):
            _write_mapping(group, value.to_dict())
        else:
            fields = [f for f in dataclasses.fields(value) if f.init]
            units = {f.name: str(f.metadata["unit"]) for f in fields if "unit" in f.metadata}
            for item in fields:
                write_value(group, item.name, getattr(value, item.name))
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
    if dataclasses.is_dataclass(value) or hasattr(value, "to_dict"):
        raise ArchiveError(f"cannot archive a {type(value).__qualname__}: it has no registered schema "
                           "(vehid.identification.dataio.storage.register_codec)")
    raise ArchiveError(f"cannot archive a value of type {type(value).__module__}.{type(value).__qualname__}")


def _write_mapping(group: h5py.Group, mapping: Mapping) -> None:
    group.attrs[_KEYS] = "[]"
    for key, item in mapping.items():
        if not isinstance(key, str):
            raise ArchiveError(f"only dicts with str keys can be archived; got key {key!r}")
        write_value(group, key, item)


def read_value(group: h5py.Group, name: str) -> Any:
    """Read member ``name`` of ``group`` as :func:`write_value` stored it.

    Parameters
    ----------
    group : h5py.Group
        The open group.
    name : str
        The member: a dataset, a group or an attribute.

    Returns
    -------
    object
        A value equal to the one written (arrays bit for bit). NumPy scalars
        come back as the matching Python scalars.

    Raises
    ------
    ArchiveError
        When there is no such member, or it names an unknown schema or class, or it cannot be rebuilt.
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
    """Read a group written by :func:`write_group` (or by :func:`write_value`) back into its value.

    Parameters
    ----------
    group : h5py.Group
        The open group.

    Returns
    -------
    object
        The value: a registered class's instance, a dict, tuple or list.
    """
    attrs = group.attrs
    if _SCHEMA in attrs or _LEGACY_DATACLASS in attrs or _LEGACY_CLASS in attrs:
        return _read_registered(group)
    encoding = attrs.get(_ENCODING)
    if encoding == "dict":
        return _read_mapping(group)
    if encoding in ("tuple", "list"):
        items = [read_value(group, str(index)) for index in range(int(attrs[_LENGTH]))]
        return tuple(items) if encoding == "tuple" else items
    raise ArchiveError(f"{group.name} is not a value written by the archive serializer")


def _read_mapping(group: h5py.Group) -> dict[str, Any]:
    keys = json.loads(group.attrs.get(_KEYS, "[]"))
    return {key: read_value(group, key) for key in keys}


def _read_registered(group: h5py.Group) -> Any:
    """A registered type's value, by the schema its group names or (older archives) by the class it names."""
    _register_identification_types()
    attrs = group.attrs
    if _SCHEMA in attrs:
        schema, version = str(attrs[_SCHEMA]), int(attrs.get(_SCHEMA_VERSION, 0))
    else:
        path = str(attrs.get(_LEGACY_DATACLASS, attrs.get(_LEGACY_CLASS)))
        if path not in LEGACY_CLASS_PATHS:
            raise ArchiveError(f"{group.name} names class {path!r}, which no registered type was stored as; "
                               "refusing to read it")
        schema, version = LEGACY_CLASS_PATHS[path], 1
    if schema not in _SCHEMAS:
        raise ArchiveError(f"{group.name} is stored with schema {schema!r}, which this workbench does not know")
    cls, known = _SCHEMAS[schema]
    if version != known:
        raise ArchiveError(f"{group.name} is stored with schema {schema!r} version {version}; "
                           f"this workbench reads version {known}")
    try:
        if hasattr(cls, "from_hdf5"):
            return cls.from_hdf5(group)
        if hasattr(cls, "from_dict"):
            return cls.from_dict(_read_mapping(group))
        present = set(group.keys()) | set(attrs.keys())
        fields = [f.name for f in dataclasses.fields(cls) if f.init and f.name in present]
        return cls(**{name: read_value(group, name) for name in fields})
    except (TypeError, ValueError, KeyError) as exc:
        raise ArchiveError(f"{group.name} does not rebuild a {schema}: {exc}") from None
