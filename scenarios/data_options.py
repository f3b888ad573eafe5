"""The command line's data options: reading, time base and preparation of one or several records.

Commands that read measured data register the options
(:func:`vehid.scenarios.commands.arguments.register_data_options`), read with
:func:`read_from_args`, prepare with :func:`preparation_options`,
report with :func:`records_summary` (public JSON keys ``records``,
``sample_jitter``, ``preparation``, ``conversions``, ``time_offset``) and
:func:`data_warnings`, and keep the prepared records and their preparation in
an archive (:func:`archive_records`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from vehid.identification.errors import InputError

if TYPE_CHECKING:  # the command line imports this module before it knows whether it will read any data
    import h5py

    from vehid.identification.data import IOData
    from vehid.identification.dataio.preparation import Preparation, ReadSettings

__all__ = ["channel_names", "settings_from_args", "read_from_args", "preparation_options",
           "records_summary", "data_warnings", "record_names",
           "archive_records", "archived_preparation", "save_model", "RECORD_PREFIX",
           "record_series", "record_series_name", "write_record_series"]

PREPARATION_MEMBER = "preparation"
RECORD_PREFIX = "identification"


def channel_names(text: str | None) -> tuple[str, ...]:
    """Channel names from a comma-separated option (empty for None); an empty list is an error."""
    if text is None:
        return ()
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    if not names:
        raise InputError("an empty column list was given")
    return names


def settings_from_args(args: Any) -> ReadSettings:
    """The :class:`ReadSettings` the options describe (``args``: the parsed command line)."""
    from vehid.identification.dataio.preparation import ReadSettings

    return ReadSettings(
        inputs=channel_names(args.inputs), outputs=channel_names(args.outputs), time_column=args.time_column, dt=args.dt,
        resample=args.resample, decimate=args.decimate, segment=args.segment,
        jitter_tolerance=args.jitter_tolerance, time_scale=getattr(args, "time_scale", None),
    )


def read_from_args(args: Any, paths: Sequence[str]) -> tuple[tuple[IOData, ...], ReadSettings]:
    """The raw records of the data files named on the command line, and the settings they were read with.

    For a hold-out split: split a raw record first, then :func:`~identification.dataio.preparation.prepare` the
    estimation part (``detrend=args.detrend, scale=args.scale, settings=settings``)
    and :func:`~identification.dataio.preparation.prepare_validation` the rest.
    """
    if not paths:
        raise InputError("give a DATA file (or --resume ARCHIVE)")
    if len(set(paths)) != len(paths):
        raise InputError("a data file is named twice")
    from vehid.identification.dataio.preparation import read_raw_records

    return read_raw_records(list(paths), settings_from_args(args))


def preparation_options(args: Any) -> dict[str, Any]:
    """The keywords of :func:`~identification.dataio.preparation.prepare` the options give (offsets and conversions)."""
    return {"detrend": args.detrend, "scale": args.scale, "steering_ratio": getattr(args, "steering_ratio", None)}


def record_series_name(prefix: str, index: int) -> str:
    """The archive name of record ``index`` (0-based) of a series: ``prefix``, ``prefix_2``, ``prefix_3``, ..."""
    return prefix if index == 0 else f"{prefix}_{index + 1}"


def write_record_series(archive: h5py.File, records: Sequence[IOData], prefix: str) -> None:
    """Store records as a series under ``prefix`` (:func:`record_series_name`), in order."""
    from vehid.identification.dataio.archive import write_record

    for index, record in enumerate(records):
        write_record(archive, record_series_name(prefix, index), record)


def record_series(stored: Mapping[str, IOData], prefix: str) -> tuple[IOData, ...]:
    """The series under ``prefix`` among an archive's records (:func:`read_records`), in order."""
    found = []
    while record_series_name(prefix, len(found)) in stored:
        found.append(stored[record_series_name(prefix, len(found))])
    return tuple(found)


def archive_records(archive: h5py.File, records: Sequence[IOData], preparation: Preparation | None) -> None:
    """Store the prepared records (``data/identification``, ``data/identification_2``, ...) and the preparation."""
    from vehid.identification.dataio.storage import write_value

    write_record_series(archive, records, RECORD_PREFIX)
    if preparation is not None:
        write_value(archive, PREPARATION_MEMBER, preparation)


def archived_preparation(archive: h5py.File) -> Preparation | None:
    """The preparation stored with an identification run (None in archives written before it was kept)."""
    from vehid.identification.dataio.preparation import Preparation
    from vehid.identification.dataio.storage import read_value

    if PREPARATION_MEMBER not in archive:
        return None
    value = read_value(archive, PREPARATION_MEMBER)
    if not isinstance(value, Preparation):
        raise InputError(f"the archive's {PREPARATION_MEMBER!r} member is not a Preparation")
    return value


MODEL_FILE_SUFFIXES = (".json", ".mat")


def _model_file_identity(path: Path):
    """A model file the workbench wrote (JSON or MATLAB with the matrices A, B, C, D), or None for any other file."""
    from vehid.identification.dataio.archive_safety import OutputIdentity

    matrices = {"A", "B", "C", "D"}
    try:
        if path.suffix.lower() == ".json":
            content = json.loads(path.read_text())
            found = isinstance(content, dict) and matrices <= content.keys() and "structure" in content
        else:
            from scipy.io import whosmat

            found = matrices <= {name for name, _, _ in whosmat(path)}
    except (OSError, ValueError, TypeError, NotImplementedError):
        return None
    return OutputIdentity("model", None) if found else None


def check_model_target(target: str, *, inputs=(), force: bool = False) -> Path:
    """Check ``--save-model`` before any work: a .json or .mat name, a writable place, nothing of the user's replaced.

    An existing file is replaced only if it is a model file of the
    workbench, or with ``force``.
    """
    from vehid.identification.dataio.archive_safety import check_output_target

    path = Path(target)
    if path.suffix.lower() not in MODEL_FILE_SUFFIXES:
        raise InputError(f"--save-model takes a .json or .mat file; got {target!r}")
    return check_output_target(path, inputs=inputs, force=force, what="model file", kind="model",
                               identify=_model_file_identity)


def save_model(model: Any, target: str, preparation: Preparation | None) -> Path:
    """Write the model, with its preparation, to a ``.json`` or ``.mat`` file."""
    path = Path(target)
    suffix = path.suffix.lower()
    if suffix == ".json":
        content = model.to_dict()
        if preparation is not None:
            content["preparation"] = preparation.as_dict()
        path.write_text(json.dumps(content, indent=2, default=str) + "\n")
        return path
    if suffix == ".mat":
        model.save_mat(path)
        if preparation is not None:
            from scipy.io import loadmat, savemat

            contents = {k: v for k, v in loadmat(path).items() if not k.startswith("__")}
            contents.update({
                "input_scale": preparation.input_scale, "output_scale": preparation.output_scale,
                "input_offset": preparation.input_offset, "output_offset": preparation.output_offset,
            })
            savemat(path, contents)
        return path
    raise InputError(f"--save-model takes a .json or .mat file; got {target!r}")
