"""How much of a measured drive a model of a moving car is identified from: the command line's defaults.

Every record `vehid identify` reads is cleaned and cut before it is prepared
(:func:`~vehid.identification.automatic.intake.clean_runs`): its spikes and drop-outs are found in
every input, output and the speed (scheduling) channel, replaced by interpolation with ``--despike``,
the ``--exclude`` windows left out, and, for models that need a moving car (``--structure
single-track``, ``--schedule`` on a speed), the samples below ``--min-speed`` (default
:data:`MIN_SPEED`; JSON ``left_out`` counts them as ``below_min_speed``), with runs shorter than
:data:`MIN_RUN_SECONDS` dropped; each contiguous run of what is left is its own record. What was found and done becomes the JSON keys ``outliers``,
``despiked``, ``left_out`` and ``excluded``
(:func:`~vehid.identification.dataio.cleaning.cleaning_summary`).
"""

from __future__ import annotations

__all__ = ["MIN_SPEED", "MIN_RUN_SECONDS"]

#: The least speed (m/s) of the samples a model of a moving car is identified from, by default: below it a
#: rolling car's slip angles are not small (the single-track model's premise) and at standstill the speed
#: channel is noise about zero, negative as often as positive.
MIN_SPEED = 5.0
#: The shortest run of moving samples used as a record of a car's model (s): its states settle from an
#: unknown start within a few of its time constants (0.05-0.3 s at and above 5 m/s for a road car), so a
#: shorter run holds little to identify from after that.
MIN_RUN_SECONDS = 2.0
