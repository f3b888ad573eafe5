"""Model files: an identified model written to ``.json`` or ``.mat`` with the preparation of its records.

The target is checked before any work (:func:`check_model_target`): a ``.json`` or ``.mat`` name, a
writable place, and nothing replaced that the workbench did not write, unless forced. A JSON file
holds the model's :meth:`to_dict` and the preparation (offsets, scale factors, reading settings); a
MATLAB file the matrices and the scale factors and offsets.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable

from ..errors import OptionError
from ..jsonable import json_default

if TYPE_CHECKING:
    from .archive_safety import OutputIdentity
    from .preparation import Preparation

__all__ = ["MODEL_FILE_SUFFIXES", "check_model_target", "json_model_kind", "save_model"]

MODEL_FILE_SUFFIXES = (".json", ".mat")


def json_model_kind(content: Any) -> str | None:
    """What a model file's JSON content holds: ``"modal"``, ``"scheduled"``, the ``kind`` a model of its own
    names (e.g. ``"single-track"``, with its ``config``), or None where it is no model file of the workbench.

    The one test of what a JSON model file is, for the readers and for the check that a file may be replaced.
    """
    if not isinstance(content, dict):
        return None
    if isinstance(content.get("kind"), str) and "config" in content:
        return content["kind"]
    if {"grid", "variable", "structure"} <= content.keys():
        return "scheduled"
    if {"structure", "A", "B", "C", "D"} <= content.keys():
        return "modal"
    return None


def _model_file_identity(path: Path) -> OutputIdentity | None:
    """A model file the workbench wrote (JSON of any :func:`json_model_kind`, or MATLAB with the matrices
    A, B, C, D), or None for any other file."""
    from .archive_safety import OutputIdentity

    matrices = {"A", "B", "C", "D"}
    try:
        if path.suffix.lower() == ".json":
            found = json_model_kind(json.loads(path.read_text())) is not None
        else:
            from scipy.io import whosmat

            found = matrices <= {name for name, _, _ in whosmat(path)}
    except (OSError, ValueError, TypeError, NotImplementedError):
        return None
    return OutputIdentity("model", None) if found else None


def check_model_target(target: str | Path, *, inputs: Iterable[str | Path | None] = (), force: bool = False,
                       suffixes: tuple[str, ...] = MODEL_FILE_SUFFIXES) -> Path:
    """Check ``save_model`` before any work: a name of ``suffixes``, a writable place, nothing of the user's
    replaced.

    An existing file is replaced only if it is a model file of the workbench, or with ``force``.
    """
    from .archive_safety import check_output_target

    path = Path(target)
    if path.suffix.lower() not in suffixes:
        raise OptionError(f"'save_model' takes a {' or '.join(suffixes)} file; got {str(target)!r}", "save_model")
    return check_output_target(path, inputs=inputs, force=force, what="model file", kind="model",
                               identify=_model_file_identity)


def save_model(model: Any, target: str | Path, preparation: Preparation | None) -> Path:
    """Write the model, with its preparation, to a ``.json`` or ``.mat`` file."""
    path = Path(target)
    suffix = path.suffix.lower()
    if suffix == ".json":
        content = model.to_dict()
        if preparation is not None:
            content["preparation"] = preparation.as_dict()
        path.write_text(json.dumps(content, indent=2, default=json_default) + "\n")
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
    raise OptionError(f"'save_model' takes a .json or .mat file; got {str(target)!r}", "save_model")
