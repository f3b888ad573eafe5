"""vehid: a vehicle-dynamics identification workbench.

The subpackages are the repository's three folders: :mod:`vehid.vehicle`
(the symbolic full-vehicle model and its simulation),
:mod:`vehid.identification` (model structures, estimators and fit metrics;
it knows nothing of vehicles) and :mod:`vehid.scenarios` (studies, reports
and the ``vehid`` command line).
"""
