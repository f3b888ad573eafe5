"""The plan of one identification: estimation records, validation records and the orders to try.

A plan is data, whatever read it: the command builds one from files
(offsets removed, channels scaled), :func:`~vehid.identification.pipeline.identify`
from records in memory. Validation comes from the tail of each estimation record
(:func:`holdout_fraction`) or from other records, each checked against the
estimation records (:func:`make_plan`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.errors import InputError, OptionError

__all__ = ["AUTO_MAX_ORDER", "AUTO_HOLDOUT", "ScheduleData", "Plan", "parse_order_option", "supported_orders", "holdout_fraction",
           "make_plan"]

AUTO_MAX_ORDER = 8
AUTO_HOLDOUT = 0.3  # fraction held out to choose an order when no validation data are given


def parse_order_option(text: Any) -> tuple[list[int], bool]:
    """``"4"``, ``"2-8"`` or ``"auto"``: the orders to try and whether to stop early (auto)."""
    value = str(text).strip().lower()
    if value == "auto":
        return list(range(1, AUTO_MAX_ORDER + 1)), True
    try:
        if "-" in value:
            low, high = (int(part) for part in value.split("-", 1))
        else:
            low = high = int(value)
    except ValueError:
        raise OptionError(f"'order' takes a whole number, a range such as 2-8, or auto; got {text!r}", "order") from None
    if low < 1 or high < low:
        raise OptionError(f"'order' {text!r}: orders must be >= 1 and the range increasing", "order")
    return list(range(low, high + 1)), False


def supported_orders(orders: list[int], auto: bool, records: tuple[IOData, ...], text: Any) -> list[int]:
    """The orders the estimation records can support: ``--order auto`` is cut to them, any other beyond them refused.

    The bound is the data start's (:func:`~identification.classical.subspace.largest_subspace_order`:
    a Hankel matrix of 2n block rows with as many columns as rows, N >= 4 n (1 + n_u + n_y) - 1
    samples for one record) and the filter's (fewer parameters than samples): docs/measured_data.md, "Orders".
    """
    from vehid.identification.models.modal_structure import ModalStructure
    from vehid.identification.classical.subspace import largest_subspace_order

    first = records[0]
    lengths = [record.n_samples for record in records]
    limit = largest_subspace_order(lengths, first.n_u, first.n_y)
    while limit > 0 and ModalStructure.default(limit, first.n_u, first.n_y).n_parameters >= sum(lengths):
        limit -= 1
    if auto:
        orders = [order for order in orders if order <= limit]
    if not orders or max(orders) > limit:
        samples = (f"{lengths[0]} estimation samples" if len(lengths) == 1
                   else f"{len(lengths)} records of {sum(lengths)} estimation samples")
        supports = f"they support orders up to {limit}" if limit else "they support no order"
        raise OptionError(f"'order' {text}: {samples} with {first.n_u} input(s) and {first.n_y} output(s) cannot "
                          f"identify a model of order {max(orders or [limit + 1])}; {supports} (the data start needs "
                          "N >= 4 n (1 + n_u + n_y) - 1 samples per record): give a lower order or a longer record",
                          "order")
    return orders


@dataclass(frozen=True, eq=False)
class ScheduleData:
    """The schedule channel of a plan's records: its name, its samples per estimation and validation record and
    its unit ("-" where unknown)."""

    channel: str
    estimation: tuple[np.ndarray, ...]
    validation: tuple[np.ndarray, ...]
    unit: str = "-"


@dataclass(frozen=True, eq=False)
class Plan:
    """The records and orders of one identification.

    ``records`` are the prepared estimation records (several identify one
    model); ``preparation`` holds their offsets and scale factors, with which
    validation records were prepared alike.
    """

    records: tuple[IOData, ...]
    validation: tuple[IOData, ...]
    validation_names: tuple[str, ...]
    orders: tuple[int, ...]
    auto: bool
    notes: tuple[str, ...] = ()
    preparation: Any = None
    held_out_count: int = 0  # the first validation records are held-out parts of the estimation records
    schedule: ScheduleData | None = None  # the schedule channel's samples per record, for the scheduled variant

    @property
    def estimation(self) -> IOData | tuple[IOData, ...]:
        """What the estimators take: the record, or the records when there are several."""
        return self.records[0] if len(self.records) == 1 else self.records

    @property
    def settle_start(self) -> bool | None:
        """Whether each record's start state is unknown (offsets removed, or several records)."""
        if self.preparation is not None and self.preparation.detrend != "none":
            return True
        return None


def holdout_fraction(order: int | str, validation: float | None, has_validation_records: bool
                     ) -> tuple[float | None, str | None]:
    """The fraction of each record held out, and a note when it is held out only to choose the order.

    ``validation`` is the fraction asked for (None: none); without it and without validation
    records an order search holds out :data:`AUTO_HOLDOUT` to choose its order.
    """
    orders, _ = parse_order_option(order)
    if validation is not None:
        if isinstance(validation, bool) or not 0 < validation < 1:
            raise OptionError(f"'validation' takes a fraction between 0 and 1; got {validation}", "validation")
        return validation, None
    if len(orders) > 1 and not has_validation_records:
        return AUTO_HOLDOUT, f"the last {AUTO_HOLDOUT:.0%} of the record held out to choose the order"
    return None, None


def _same_samples(a: IOData, b: IOData) -> bool:
    """Whether two records start with the same samples (one experiment, perhaps cut to another length)."""
    n = min(a.n_samples, b.n_samples)
    if a.u.shape[1] != b.u.shape[1] or a.y.shape[1] != b.y.shape[1] or n < 2:
        return False
    return all(np.allclose(x[:n], z[:n], rtol=1e-9, atol=1e-12 * max(float(np.max(np.abs(z[:n]))), 1e-300))
               for x, z in ((a.u, b.u), (a.y, b.y)))


def make_plan(records: tuple[IOData, ...], *, order: int | str, validation: Sequence[tuple[str, Any]] = (),
              load: Callable[[Any], IOData] = lambda record: record, held_out: tuple[IOData, ...] = (),
              fraction: float | None = None, note: str | None = None, preparation: Any = None) -> Plan:
    """The plan of one identification: estimation records, their held-out parts and the validation records.

    ``validation`` names each further validation source (a file's path, a record's source) beside
    what ``load`` turns into a prepared record; each is refused where it does not match the
    estimation records' channels or repeats their samples.
    """
    orders, auto = parse_order_option(order)
    first = records[0]
    orders = supported_orders(orders, auto, records, order)
    validation_records = list(held_out)
    names = [f"last {fraction:g} of the record" if fraction is not None else "held-out part"] * len(held_out)
    if len(held_out) > 1:
        names = [f"{name} {i + 1}" for i, name in enumerate(names)]
    for path, source in validation:
        record = load(source)
        if (record.n_u, record.n_y) != (first.n_u, first.n_y):
            raise InputError(f"{path} has {record.n_u} inputs and {record.n_y} outputs; the record has {first.n_u} and {first.n_y}")
        if record.input_names != first.input_names or record.output_names != first.output_names:
            raise InputError(f"{path} names its columns differently from the identification record")
        if any(_same_samples(record, estimation) for estimation in records):
            raise OptionError(f"{path} holds the same samples as the estimation record: validating on it would score "
                              "the model on its own data (where the validation record lies in other channels of the "
                              "file, name them with 'validation_inputs' and 'validation_outputs')",
                              "validation_inputs", "validation_outputs")
        validation_records.append(record)
        names.append(str(path))
    return Plan(tuple(records), tuple(validation_records), tuple(names), tuple(orders), auto, (note,) if note else (),
                preparation, len(held_out))
