"""Reading a car's measured drive for the commands that drive the vehicle model along it.

``vehid simulate --replay`` and ``vehid calibrate`` read one steer channel and the channels beside it
(speed, measured outputs, checks) through the workbench's readers, and multiply each by its
``--scale`` factor (a unit or a sign) as it is taken.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

from vehid.identification.errors import InputError

if TYPE_CHECKING:  # the command line imports this module before it reads any data
    import numpy as np

    from vehid.identification.data import IOData

__all__ = ["read_drive", "scaled_channels"]


def read_drive(path: Path, steer: str, channels: Sequence[str], scale_items: Any, *, what: str,
               **settings: Any) -> tuple[IOData, dict[str, float]]:
    """The log's steer and ``channels`` as read (``settings``: :class:`ReadSettings` fields), and the scales.

    ``what`` names the channels in the message refusing a ``--scale`` of another channel.
    """
    from vehid.identification.dataio.preparation import ReadSettings, parse_scale, read_record

    data = read_record(path, ReadSettings(inputs=(steer,), outputs=tuple(channels), **settings))
    scale = parse_scale(scale_items)
    unknown = sorted(set(scale) - {steer, *channels})
    if unknown:
        raise InputError(f"--scale names {unknown[0]!r}, which is not {what}")
    return data, scale


def scaled_channels(data: IOData, steer: str, scale: dict[str, float]) -> Callable[[str], np.ndarray]:
    """A function giving a channel of ``data`` by name (the steer, or any output) times its scale factor."""
    def channel(name: str) -> np.ndarray:
        values = data.u[:, 0] if name == steer else data.y[:, data.output_names.index(name)]
        return values * scale.get(name, 1.0)

    return channel
