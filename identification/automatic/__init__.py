"""The automatic identification pipeline behind :func:`vehid.identification.identify` and `vehid identify`.

Modules, in the order a run meets them:

``options``
    :class:`IdentifyOptions`, every setting defined and checked once (imports nothing heavy).
``plan``
    The records and orders of one run: estimation records, held-out tails, validation records.
``scoring``
    The run's one rule for scoring every candidate, the decision margins' form and the warnings.
``refinement``
    A linear model refined by its simulation error, and that refinement cross-validated.
``tuning``
    The IEKF's settings, and its p and Q schedule by cross-validation.
``returned``
    The model a run returns, the filter's or its start's (refined or not), the open-loop-unstable
    treatment, and each decision's margin and note.
``orders``
    The order search and the order chosen.
``iekf_order``
    One IEKF run of one order: the decisions before it, the run, the model returned.
``nonlinear``
    The spline-nonlinear model started from the linear one, returned where it validates better.
``reported_checks``
    What is reported beside the scores: modes with standard deviations, residual tests, the data's keys.
``scheduled``
    The speed-scheduled variant: a family started from the model identified, returned where it
    validates better.
``run``
    One run on a plan, with checkpoints for a caller that keeps it on disk.
``result``
    The typed :class:`Identification` and its summary under the public JSON keys.

Nothing here reads files or knows of vehicles: the command line reads files into a plan, and a
speed-scheduled model takes its schedule channel as data.
"""
