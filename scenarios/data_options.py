"""Where the data of an identification are kept: the archive's record series and preparation, and model files.

The command line's data options are registered and read back in :mod:`vehid.scenarios.commands.arguments`
(:func:`~vehid.scenarios.commands.arguments.reading_settings`); the library keeps the prepared records
and their preparation in an archive (:mod:`vehid.identification.automatic.archiving`) and writes model
files (:mod:`vehid.identification.dataio.model_files`). Their names stay reachable here.
"""

from __future__ import annotations

from vehid.identification.automatic.archiving import (RECORD_PREFIX, archive_records, archived_preparation,
                                                      record_series, record_series_name, write_record_series)
from vehid.identification.dataio.model_files import check_model_target, save_model

__all__ = ["archive_records", "archived_preparation", "check_model_target", "save_model", "RECORD_PREFIX",
           "record_series", "record_series_name", "write_record_series"]
