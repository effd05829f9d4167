"""What an engineer reads first: the ``summary`` section of ``report.json`` (:class:`Summary`), built from the
calibration report by :func:`summarize`, the one owner of the verdict and of the one-line model.

It states whether a simulated device took part, the chosen model (convention, identified parameters, physical
effects with their values, residual layer, joint set, drift model) with the reason for each choice (taken from
the report's own sections), the final model's held-out figures and their ratio to the noise floor, and the verdict
against the config's optional ``acceptance`` criterion. Rendered by ``campaign.report.summary_text`` (terminal)
and the HTML report's first section.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from campaign.io.json_fields import (count_field, figure_field, get_field, list_field, record_dict, record_field,
                                     records_field, text_field)

from robocal.measure.noise import noise_max_mm

from .report_sections import ErrorFigures, HeldOutOutliers

PASS, FAIL, NO_CRITERION, NO_TEST_SET = "pass", "fail", "no acceptance criterion", "no held-out test set"


@dataclass(frozen=True)
class EffectValue:
    """One fitted parameter of a physical effect, in the unit ``robocal.effects`` reports it in."""
    name: str
    value: float
    unit: str

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "EffectValue":
        return cls(text_field(d, "name"), figure_field(d, "value"), text_field(d, "unit"))


@dataclass(frozen=True)
class ChosenEffect:
    """A physical effect the final model carries: its label (``backlash(J1,2,3)``) and fitted values."""
    label: str
    values: tuple[EffectValue, ...]

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "ChosenEffect":
        return cls(text_field(d, "label"), records_field(d, "values", EffectValue.from_dict))


@dataclass(frozen=True)
class ModelSummary:
    """The chosen model: kinematic ``convention`` with Hayati beta joints, parameters identified / fixed at
    nominal, physical ``effects``, residual layer, joint set (``readback`` | ``commanded``), tracker drift model
    (in words)."""
    convention: str
    hayati_joints: tuple[int, ...]
    n_identified: int
    n_fixed: int
    effects: tuple[ChosenEffect, ...]
    residual: str
    joints: str
    drift: str

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "ModelSummary":
        return cls(text_field(d, "convention"), tuple(list_field(d, "hayati_joints")),
                   count_field(d, "n_identified"), count_field(d, "n_fixed"),
                   records_field(d, "effects", ChosenEffect.from_dict),
                   text_field(d, "residual"), text_field(d, "joints"), text_field(d, "drift"))


REASON_KEYS = ("convention", "parameters", "effects", "residual", "joints", "drift")


@dataclass(frozen=True)
class Reasons:
    """Why each part of the model was chosen, one short sentence each (from the report's sections)."""
    convention: str
    parameters: str
    effects: str
    residual: str
    joints: str
    drift: str

    def items(self) -> tuple[tuple[str, str], ...]:
        return tuple((k, getattr(self, k)) for k in REASON_KEYS)

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "Reasons":
        return cls(*(text_field(d, k) for k in REASON_KEYS))


@dataclass(frozen=True)
class Verdict:
    """The final model's held-out figures against ``acceptance`` (mm bounds, None = not set): ``result`` is
    ``pass``, ``fail``, or why there is no verdict; ``failed`` names each bound exceeded; ``below_noise`` each bound
    a perfect model would fail on the measured noise alone (``AcceptanceConfig.below_noise``), with
    ``noise_max_mm`` the median largest noise-only error at the test set's size (None without a verdict)."""
    max_rms_mm: float | None
    max_mm: float | None
    result: str
    failed: tuple[str, ...] = ()
    below_noise: tuple[str, ...] = ()
    noise_max_mm: float | None = None

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "Verdict":
        return cls(figure_field(d, "max_rms_mm"), figure_field(d, "max_mm"), text_field(d, "result"),
                   tuple(list_field(d, "failed", True) or ()), tuple(list_field(d, "below_noise", True) or ()),
                   figure_field(d, "noise_max_mm"))


@dataclass(frozen=True)
class Summary:
    """``report.json``'s ``summary``: ``simulated_devices`` (roles behind ``mock://``; None: not recorded, e.g.
    data from a CSV), the ``model`` and its ``reasons``, the final model on the held-out test set (``held_out``,
    None without test rows), the noise floor (mm) and RMS / floor, the acceptance ``verdict``, and for data without
    devices (a CSV) their ``provenance`` ("imported from FILE ...; devices not recorded")."""
    simulated_devices: tuple[str, ...] | None
    model: ModelSummary
    reasons: Reasons
    held_out: ErrorFigures | None
    noise_floor_mm: float
    rms_over_floor: float | None
    verdict: Verdict
    provenance: str | None = None
    held_out_outliers: HeldOutOutliers | None = None   # absurd held-out errors, named, and the figures without

    @property
    def simulated(self) -> bool:
        return bool(self.simulated_devices)

    def to_dict(self) -> dict:
        return record_dict(self, omit_none=("held_out_outliers",))

    @classmethod
    def from_dict(cls, d: Mapping) -> "Summary":
        sim = get_field(d, "simulated_devices", True)
        return cls(None if sim is None else tuple(sim), record_field(d, "model", ModelSummary.from_dict),
                   record_field(d, "reasons", Reasons.from_dict),
                   record_field(d, "held_out", ErrorFigures.from_dict, True), figure_field(d, "noise_floor_mm"),
                   figure_field(d, "rms_over_floor"), record_field(d, "verdict", Verdict.from_dict),
                   text_field(d, "provenance", True),
                   record_field(d, "held_out_outliers", HeldOutOutliers.from_dict, True))


def summarize(report, acceptance=None) -> Summary:
    """The summary of a ``CalibrationReport`` (with its identification, when from a log) against ``acceptance``
    (``campaign.config.schema.AcceptanceConfig`` or None)."""
    final = report.final
    held = final.test if final is not None and report.n.test and final.test.rms_mm is not None else None
    floor = report.noise_floor_mm
    ratio = held.rms_mm / floor if held is not None and floor else None
    ident = dict(report.identification)
    sim = ident.get("simulated_devices")
    return Summary(None if sim is None else tuple(sim), _model(report), _reasons(report), held, floor, ratio,
                   verdict(held, acceptance, floor), ident.get("provenance"),
                   None if held is None else final.test_outliers)


def verdict(held: ErrorFigures | None, acceptance, floor_mm: float | None = None) -> Verdict:
    """Pass when every configured bound holds on the held-out figures (mm); with the measured noise floor
    ``floor_mm``, the bounds that noise alone would fail are named."""
    rms_max = None if acceptance is None else acceptance.max_rms_mm
    max_max = None if acceptance is None else acceptance.max_mm
    if rms_max is None and max_max is None:
        return Verdict(None, None, NO_CRITERION)
    if held is None:
        return Verdict(rms_max, max_max, NO_TEST_SET)
    checks = (("max_rms_mm", held.rms_mm, rms_max), ("max_mm", held.max_mm, max_max))
    failed = tuple(name for name, value, bound in checks if bound is not None and value > bound)
    if not floor_mm:
        return Verdict(rms_max, max_max, FAIL if failed else PASS, failed)
    return Verdict(rms_max, max_max, FAIL if failed else PASS, failed, acceptance.below_noise(floor_mm, held.n),
                   noise_max_mm(floor_mm, held.n))


def _model(report) -> ModelSummary:
    cell = report.cell or {}
    prep = report.preparation or {}
    identified = sum(p.identified for p in report.parameters)
    drift = prep.get("drift") or {}
    return ModelSummary(str(cell.get("convention", "dh")), tuple(cell.get("hayati_joints") or ()), identified,
                        len(report.parameters) - identified, _effects(report),
                        report.method.residual if report.method and report.method.residual else "none",
                        str((prep.get("joints") or {}).get("used", "commanded")), _drift(drift))


def _drift(drift: Mapping) -> str:
    """The tracker drift model in words: none, or its polynomial degree in time (translation, or with rotation)."""
    if not drift.get("applied"):
        return "none" if drift.get("nests") else "none (no reference nests)"
    model = drift.get("model") or {}
    how = "translation and rotation" if model.get("rotation") else "translation"
    return f"degree {model.get('degree', '?')} in time, {how}, from {drift.get('nests')} nests"


def _effects(report) -> tuple[ChosenEffect, ...]:
    """The physical effects of the final model (none when its layer sits on the geometry alone)."""
    fx = report.effects
    if fx is None or not fx.fitted or (report.residual_choice and report.residual_choice.effects_left_out):
        return ()
    taken = list((fx.selection or {}).get("taken") or [])
    labels = taken if len(taken) == len(fx.fitted) else [fe["name"] for fe in fx.fitted]
    return tuple(ChosenEffect(label, tuple(EffectValue(n, p["value"], p["unit"]) for n, p in fe["params"].items()))
                 for label, fe in zip(labels, fx.fitted))


def _reasons(report) -> Reasons:
    prep = report.preparation or {}
    return Reasons(
        "configured (robot.convention, robot.hayati_joints)",
        f"{sum(not p.identified for p in report.parameters)} fixed at nominal: not identifiable from this pose "
        "set (see Identified parameters)" if any(not p.identified for p in report.parameters)
        else "every candidate identifiable from this pose set",
        _effects_reason(report), _residual_reason(report),
        str((prep.get("joints") or {}).get("why", "not recorded")),
        str((prep.get("drift") or {}).get("why", "not recorded")))


def _effects_reason(report) -> str:
    setting = report.method.effects if report.method else None
    counts = None if report.effects is None else report.effects.counts
    if counts is not None:
        how = "forward selection by cross-validation on the calibration points"
        left_out = () if report.residual_choice is None else report.residual_choice.effects_left_out
        if left_out:
            return (f"{how}: {taken_of_tried(counts)} ({', '.join(left_out)}), then left out: the geometry with a "
                    "trend + GPR layer predicted better in cross-validation (see the residual layer)")
        return f"{how}: {taken_of_tried(counts)}"
    if setting == "list":
        return "configured (calibration.effects)"
    if setting in (None, "none", "off"):
        return "none configured (calibration.effects)"
    return f"calibration.effects: {setting}"


def taken_of_tried(counts) -> str:
    """"2 of 22 candidates taken" (``report_sections.EffectCounts``): the one wording of the count everywhere."""
    return f"{counts.taken} of {counts.tried} candidates taken"


def _residual_reason(report) -> str:
    ch, m = report.residual_choice, report.method
    if m is not None and m.residual_config not in (None, "auto"):
        return f"configured (calibration.residual: {m.residual_config})"
    if ch is not None and ch.candidates:
        return (f"chosen by {ch.folds}-fold cross-validation on the calibration points among "
                f"{', '.join(ch.candidates)} (a layer is kept when it beats none by more than one standard error of "
                "the CV difference)")
    return "no candidate layer"
