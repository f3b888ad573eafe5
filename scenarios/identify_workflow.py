"""The automatic pipeline's steps under their former name.

They live in :mod:`vehid.identification.automatic.steps` (the plan in
:mod:`~vehid.identification.automatic.plan`); this name resolves to that very
module object, so that code importing ``vehid.scenarios.identify_workflow``
keeps working and sees (and may replace) the same functions the pipeline calls.
"""

import sys

from vehid.identification.automatic import steps

sys.modules[__name__] = steps
