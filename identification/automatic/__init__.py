"""The automatic identification pipeline behind :func:`vehid.identification.identify` and `vehid identify`.

Modules, in the order a run meets them:

``options``
    :class:`IdentifyOptions`, every setting defined and checked once (imports nothing heavy).
``plan``
    The records and orders of one run: estimation records, held-out tails, validation records.
``steps``
    The decisions: p and Q schedule by cross-validation, the open-loop-unstable treatment,
    start or filter, order search, scores, warnings and the spline-nonlinear model.
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
