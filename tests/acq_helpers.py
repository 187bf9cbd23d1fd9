"""Helpers shared by the acquisition tests (imported by name: pytest puts this folder on sys.path)."""

import csv
import io
import math

import numpy as np


class Lambertian:
    """f_r = rho/π per channel: the value every frame must calibrate back to."""

    def __init__(self, rho):
        self.rho = np.atleast_1d(np.asarray(rho, float))
        self.channels = ("value",) if self.rho.size == 1 else ("R", "G", "B")

    def params(self):
        return {"reference": "lambertian", "rho": self.rho.tolist()}

    def __call__(self, wi, wr):
        wi = np.asarray(wi, float)
        return np.broadcast_to(self.rho / math.pi, wi.shape[:-1] + (self.rho.size,)).copy()


#: A quick rig: 2 geometries x 4 orientations (step 30°), 12-pixel frames.
SMALL_RIG = dict(protocol="paper", step_deg=30.0, size=12, margin=2, roi_inset=1)



def edit_manifest(path, edit, add_columns=()):
    """Rewrite a manifest: ``edit(rows) -> rows`` on the list of row dicts (header kept).

    ``add_columns`` are appended to the column row (empty in every row before ``edit``).
    """
    lines = path.read_text().splitlines(keepends=True)
    header = [ln for ln in lines if ln.startswith("#")]
    body = "".join(ln for ln in lines if not ln.startswith("#"))
    reader = csv.DictReader(io.StringIO(body))
    columns = list(reader.fieldnames) + list(add_columns)
    rows = edit([{**r, **{c: "" for c in add_columns}} for r in reader])
    out = io.StringIO()
    writer = csv.DictWriter(out, columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    path.write_text("".join(header) + out.getvalue())
    return path


def predicted_sigma(
    sensor, f_r, theta_i, exposure_s, white_exposure_s, n_roi,
    white_reflectance=0.99, white_rate_e_per_s=2.0e5, n_dark=1,
):
    """Standard deviation of an ingested f_r predicted from the sensor model alone.

    Per ROI pixel, dark-subtracted: var = Sensor.pixel_sigma_dn² (shot, dark, read noise
    and rounding) for the frame, plus the dark master's own over ``n_dark`` frames;
    the ROI mean divides by ``n_roi``.  f_r = (S/t_S)/(W/t_W)·R/π, so the relative
    variances of S and W add.  (Sample and white sharing one dark frame correlate
    slightly; the dark term is < 0.1 % of the shot noise here, so this is ignored.)
    """
    K = math.pi * white_rate_e_per_s
    g = sensor.gain_e_per_dn

    def rel_sigma(signal_rate_e, t):
        signal_e = signal_rate_e * t
        var_frame = sensor.pixel_sigma_dn(signal_e, t) ** 2
        var_dark = sensor.pixel_sigma_dn(0.0, t) ** 2 / n_dark
        return np.sqrt((var_frame + var_dark) / n_roi) / (signal_e / g)

    cos_i = np.cos(theta_i)
    rel_s = rel_sigma(K * np.asarray(f_r) * cos_i[:, None], np.asarray(exposure_s)[:, None])
    rel_w = rel_sigma(K * white_reflectance / math.pi * cos_i, np.asarray(white_exposure_s))
    return np.asarray(f_r) * np.sqrt(rel_s**2 + rel_w[:, None] ** 2)


def exposures(result):
    """(sample exposure, exposure of its same-geometry white) per measurement row."""
    rows = {r.file: r for r in result.manifest.rows}
    whites = {(r.theta_i_deg, r.theta_r_deg): r.exposure_s for r in result.manifest.of_kind("white")}
    files = result.measurement.provenance["file"]
    t_s = np.array([rows[f].exposure_s for f in files])
    t_w = np.array([whites[(rows[f].theta_i_deg, rows[f].theta_r_deg)] for f in files])
    return t_s, t_w
