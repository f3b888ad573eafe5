"""How sure a model is: the checks (:mod:`vehid.identification.automatic.reported_checks`) and their text
(:mod:`vehid.identification.automatic.text`), under the names the studies import.

The public JSON keys of the checks (a contract once released) are listed in
:mod:`vehid.identification.automatic.reported_checks`.
"""

from __future__ import annotations

from vehid.identification.automatic.reported_checks import model_residual_tests, uncertainty_summary
from vehid.identification.automatic.text import mode_lines, uncertainty_lines

__all__ = ["model_residual_tests", "uncertainty_summary", "uncertainty_lines", "mode_lines"]
