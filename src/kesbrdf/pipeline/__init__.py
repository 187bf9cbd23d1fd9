"""The pipeline: the paper's steps as pure functions of typed objects (docs/pipeline.md).

``kesbrdf demo``, the batch engine (:mod:`kesbrdf.batch.steps`) and the compare
renderer (:mod:`kesbrdf.render.compare`) run the same steps, so a fabric gets the same
model, the same validation and the same files whichever of them ran it:

=========  ==============================  =======================================
step       takes                           returns
=========  ==============================  =======================================
ingest     a manifest, a CSV or nothing    :class:`Ingested` (the measurement)
           (the embedded sample)
fit        a measurement, :class:`FitSpec` :class:`Fitted` (model, selection report,
                                           content hash)
validate   :class:`Fitted`, measurement,   :class:`Validated` (round trip, leave-one-
           reference                       orientation-out, held-out reference,
                                           diagnostics)
report     ``ReportInputs``                the HTML file (:mod:`.outputs`)
export     :class:`Fitted`, formats        :class:`~kesbrdf.pipeline.outputs.Exported`
preview    :class:`Fitted`, settings       :class:`~kesbrdf.pipeline.outputs.Preview`
=========  ==============================  =======================================

This module holds the steps up to validation (the ``fitting`` layer: the render and
export views import it, e.g. the compare renderer's fit).  The steps that draw or
write files for other tools, :func:`~kesbrdf.pipeline.outputs.report`,
:func:`~kesbrdf.pipeline.outputs.export` and :func:`~kesbrdf.pipeline.outputs.preview`,
are in :mod:`kesbrdf.pipeline.outputs`, above the views.

A step never prints and never looks at the clock: callers time and report it.  The
fit rule is one: :func:`fit` is :func:`kesbrdf.fit` with the options a user gave
(``kind="auto"`` compares with the woven-cloth prior unless options were given),
exactly as ``kesbrdf fit`` runs it.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from kesbrdf.errors import KesbrdfError

__all__ = ["Ingested", "FitSpec", "Fitted", "Validated", "ingest", "fit", "validate", "model_sha256",
           "protocol_of", "FIT_OPTION_NAMES"]

#: The fit options a catalogue row or a command line may set (:func:`kesbrdf.fit`'s
#: per-kind options); an empty value keeps the library default.
FIT_OPTION_NAMES = ("orientations", "fallback", "body", "interpolation", "warp_deg")


# -- ingest -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Ingested:
    """A measurement and where it came from.

    Attributes
    ----------
    measurement : Measurement
    source : str
        ``"manifest"`` (camera frames → values), ``"csv"`` or ``"embedded"`` (the
        embedded simulated CSV).
    path : Path or None
        The file read (None for the embedded sample's manifest-free form).
    counts : dict
        Frames per status (manifests only: used, saturated, ...).
    dropped : list of dict
        Frames not used, with their reason (manifests only).
    raw : bytes
        The bytes read (CSV inputs: a batch keeps them as given).
    """

    measurement: object
    source: str
    path: Path | None = None
    counts: dict = field(default_factory=dict)
    dropped: list = field(default_factory=list)
    raw: bytes = b""


def is_manifest(path) -> bool:
    """True when ``path`` starts with the ``# kesbrdf-manifest`` line (a camera-frame manifest)."""
    from kesbrdf.io.files import open_regular

    with open_regular(Path(path)) as fh:  # a FIFO or a device is refused, never read
        head = fh.read(256).decode("utf-8", "replace").lstrip("\ufeff").lstrip()
    return head.startswith("# kesbrdf-manifest")


def ingest(source=None, *, saturation: str = "reject", name: str | None = None) -> Ingested:
    """Read a measurement: a manifest of camera frames (calibrated to values), a CSV,
    or with ``source=None`` the embedded sample (its frames when the acquisition part
    is installed, else its simulated CSV).

    ``name`` labels a CSV's rows in error messages (default: the path).
    """
    from kesbrdf.io.measurement_csv import parse_measurement
    from kesbrdf.measure import demo_data

    if source is None:
        manifest = demo_data.embedded_manifest()
        if manifest is None:
            path = demo_data.embedded_measurement()
            data = path.read_bytes()
            m = parse_measurement(data.decode("utf-8-sig"), source=str(path), sha256=hashlib.sha256(data).hexdigest())
            return Ingested(m, "embedded", path, raw=data)
        source = manifest
    path = Path(source)
    if is_manifest(path):
        from kesbrdf.measure.acquisition.ingest import ingest as ingest_frames

        res = ingest_frames(path, saturation=saturation)
        return Ingested(res.measurement, "manifest", path, res.counts(),
                        [dict(r.__dict__) for r in res.summary if r.status != "used"])
    from kesbrdf.io.files import read_regular

    data = read_regular(path)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise KesbrdfError(f"{path}: expected a measurement CSV (UTF-8 text), got binary data") from None
    m = parse_measurement(text, source=str(name or path), sha256=hashlib.sha256(data).hexdigest())
    return Ingested(m, "csv", path, raw=data)


def protocol_of(measurement) -> str | None:
    """The virtual-gonioreflectometer protocol whose geometry ``measurement`` has.

    ``"paper"``: every row in the plane of incidence with θ_i + θ_r = 90° (one incidence
    line per orientation, the paper's STEP 1); ``"dense"``: in-plane with several
    incidence angles per orientation; None: out-of-plane rows (no protocol re-measures
    them).  Read from the directions, never from the file's labels.
    """
    m = measurement
    if len(m) == 0 or not np.all(m.is_in_plane):
        return None
    return "paper" if np.allclose(m.theta_i + m.theta_r, np.pi / 2, atol=1e-6) else "dense"


# -- fit --------------------------------------------------------------------------------
@dataclass(frozen=True)
class FitSpec:
    """How to fit: the rule of ``kesbrdf fit``.

    Attributes
    ----------
    kind : str
        ``"auto"`` (the default rule, docs/models.md) or a fitter name.
    options : mapping
        Fit options given by the user (:data:`FIT_OPTION_NAMES` and per-kind ones);
        only these go to the fitter, the library defaults apply to the rest.
    strict : bool
        The K(φ) ≤ 0 fallback becomes an error.
    compare : bool
        ``kind="auto"``: compare the row-based choice with the woven-cloth prior
        (``kesbrdf fit --no-compare`` is False).
    """

    kind: str = "auto"
    options: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    strict: bool = False
    compare: bool = True

    def __post_init__(self):
        object.__setattr__(self, "options", MappingProxyType(dict(self.options)))

    @classmethod
    def from_row(cls, row: dict) -> "FitSpec":
        """The spec of a catalogue row (``kind`` and :data:`FIT_OPTION_NAMES`; empty = default)."""
        options = {k: row[k] for k in FIT_OPTION_NAMES if row.get(k) not in (None, "")}
        return cls(kind=row.get("kind") or "auto", options=options)

    def to_json(self) -> dict:
        return {"kind": self.kind, "options": dict(self.options), "strict": self.strict, "compare": self.compare}


def model_sha256(model) -> str | None:
    """SHA-256 of a model's content (kind, channels, parameters, payload arrays); None
    for an object without content (a plain callable).  Equal for a model and the file it
    was saved to and read back from; the analytic-fit cache keys on it."""
    to_payload = getattr(model, "to_payload", None)
    if to_payload is None:
        return None
    try:
        fields, arrays = to_payload()
    except NotImplementedError:
        return None

    def default(o):
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, (np.floating, np.integer)):
            return o.item()
        return str(o)

    h = hashlib.sha256()
    head = {
        "kind": getattr(model, "kind", type(model).__name__),
        "channels": list(getattr(model, "channels", ())),
        "parameters": getattr(model, "parameters", {}),
        "fields": fields,
    }
    h.update(json.dumps(head, sort_keys=True, default=default).encode())
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


@dataclass
class Fitted:
    """A fitted model, why it was chosen, and its content hash.

    Every later step (figures, report, renders, exports, viewer) reads this one model.
    """

    model: object
    report: object  # kesbrdf.fitting.FitReport
    spec: FitSpec
    sha256: str

    @property
    def kind(self) -> str:
        return self.model.kind

    def headline(self) -> str:
        """One line naming the model: kind, content hash and why the fit chose it."""
        return f"{self.kind} model (sha256 {self.sha256[:12]}): {self.report.reason}"

    def selection(self) -> dict:
        """The fit's selection report (:meth:`kesbrdf.fitting.FitReport.to_dict`)."""
        return self.report.to_dict()

    def save(self, path) -> Path:
        self.model.save(path)
        return Path(path)


def fit(measurement, spec: FitSpec | None = None) -> Fitted:
    """Fit ``measurement`` by ``spec`` (default: ``kind="auto"`` with the prior comparison,
    as ``kesbrdf fit``): :func:`kesbrdf.fit`."""
    from kesbrdf.fitting import fit as fit_model

    spec = spec or FitSpec()
    model, report = fit_model(measurement, kind=spec.kind, strict=spec.strict, compare=spec.compare,
                              **dict(spec.options))
    return Fitted(model, report, spec, model_sha256(model) or "")


# -- validate ---------------------------------------------------------------------------
@dataclass
class Validated:
    """The validation of a fitted model: each part None when its inputs are missing.

    Attributes
    ----------
    round_trip : dict
        The model against every sample (:func:`kesbrdf.validate.compare.validate`).
    leave_one_orientation_out : dict or None
        KES interpolation predicting each bias from the others (paper-protocol
        geometry only, :func:`~kesbrdf.validate.compare.leave_one_orientation_out`); a
        failure is ``{"error": ...}``.
    reference : dict or None
        KES and the baselines against the reference (:func:`~kesbrdf.validate.compare.compare_reference`).
    held_out : dict or None
        The model against the reference re-measured at held-out orientations in the
        measurement's protocol (:func:`protocol_of`).
    diagnostics : dict
        :func:`kesbrdf.validate.diagnostics.diagnose`.
    """

    round_trip: dict
    diagnostics: dict
    leave_one_orientation_out: dict | None = None
    reference: dict | None = None
    held_out: dict | None = None

    def metrics(self) -> dict:
        """The metric parts present, as the report and ``validation.json`` show them."""
        out = {"round_trip": self.round_trip}
        for key in ("leave_one_orientation_out", "reference", "held_out"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out

    def numbers(self) -> dict:
        """Headline numbers: fit NRMSE/RMSE, worst leave-one-out NRMSE, held-out NRMSE."""
        def finite(x):
            x = float(x)
            return x if np.isfinite(x) else None

        allm = self.round_trip["metrics"]["all"]
        out = {"fit_nrmse": finite(allm["nrmse"]), "fit_rmse": finite(allm["rmse"])}
        loo = self.leave_one_orientation_out
        if loo is not None:
            errs = [v["metrics"]["all"]["nrmse"] for v in loo.values() if isinstance(v, dict) and v.get("possible")]
            out["loo_nrmse"] = finite(max(errs)) if errs else None
        if self.held_out is not None:
            out["ref_nrmse"] = finite(self.held_out["metrics"]["all"]["nrmse"])
        return out


def validate(fitted: Fitted, measurement, reference=None, *, mapping: str | None = None,
             fallback: str | None = None, baselines: bool = True, held_out: bool = True) -> Validated:
    """Validate ``fitted`` on ``measurement`` (and ``reference``, a BRDF callable, when given).

    ``baselines``: compare KES and the baselines with the reference
    (:attr:`Validated.reference`); ``held_out``: the model itself at held-out
    orientations re-measured from the reference (:attr:`Validated.held_out`).
    """
    from kesbrdf.validate.compare import HELD_OUT_DEG, compare_reference, leave_one_orientation_out
    from kesbrdf.validate.compare import validate as validate_model
    from kesbrdf.validate.diagnostics import diagnose

    model, m = fitted.model, measurement
    result = Validated(round_trip=validate_model(model, m, mapping), diagnostics=diagnose(model))
    protocol = protocol_of(m)
    # the KES fits and baselines of these checks read their tables with the mapping asked
    # for, else with their own (the one new fits record)
    kes_kwargs = {"mapping": mapping if mapping in ("deviation", "halfvector", "paper") else None}
    if fallback:
        kes_kwargs["fallback"] = fallback
    if protocol == "paper":
        try:
            result.leave_one_orientation_out = leave_one_orientation_out(m, **kes_kwargs)
        except KesbrdfError as exc:
            result.leave_one_orientation_out = {"error": str(exc)}
    if reference is not None and baselines:
        try:
            result.reference = compare_reference(m, reference, **kes_kwargs)
        except KesbrdfError as exc:
            result.reference = {"error": str(exc)}
    if reference is not None and held_out and protocol is not None:
        from kesbrdf.measure.gonio import measure

        held = measure(reference, protocol=protocol, orientations_deg=HELD_OUT_DEG)
        result.held_out = {"held_out_orientations_deg": list(HELD_OUT_DEG), "protocol": protocol,
                           **validate_model(model, held, mapping)}
    return result
