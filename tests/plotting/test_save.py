"""kesbrdf.plotting.save: saved figures are valid files carrying their provenance."""

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from kesbrdf._version import __version__
from kesbrdf.errors import KesbrdfError
from kesbrdf.plotting.save import (
    attach_provenance,
    describe,
    figure_bytes,
    provenance,
    read_png_text,
    save_figure,
)

SHA = "ab" * 32
DC = "{http://purl.org/dc/elements/1.1/}"


@pytest.fixture
def small_fig(fig):
    ax = fig.add_subplot()
    ax.plot([0, 1], [0, 1])
    return attach_provenance(fig, {"kesbrdf_version": __version__, "input_sha256": SHA,
                                   "parameters": {"figure": "test", "gamma_deg": np.array([-60.0, 0.0])}})


def test_png_has_provenance_chunks(small_fig, tmp_path):
    path = save_figure(small_fig, tmp_path / "f.png", record={"model_file_sha256": "cd" * 32})
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 1000
    text = read_png_text(data)
    assert text["kesbrdf_version"] == __version__
    assert text["input_sha256"] == SHA
    assert json.loads(text["parameters"]) == {"figure": "test", "gamma_deg": [-60.0, 0.0]}
    record = json.loads(text["kesbrdf_provenance"])
    assert record["model_file_sha256"] == "cd" * 32
    from PIL import Image  # an independent PNG reader agrees

    with Image.open(path) as im:
        im.load()
        assert im.text["input_sha256"] == SHA
    assert [p.name for p in tmp_path.iterdir()] == ["f.png"]  # no temporary left behind


def test_svg_has_provenance_metadata(small_fig, tmp_path):
    path = save_figure(small_fig, tmp_path / "f.svg")
    root = ET.parse(path).getroot()  # well-formed XML
    assert root.tag.endswith("svg")
    desc = root.find(f".//{DC}description")
    assert json.loads(desc.text)["input_sha256"] == SHA
    assert root.find(f".//{DC}source").text == SHA
    assert root.find(f".//{DC}date") is None  # no timestamp: reproducible


def test_svg_and_png_are_reproducible(small_fig):
    assert figure_bytes(small_fig, "svg") == figure_bytes(small_fig, "svg")
    assert figure_bytes(small_fig, "png") == figure_bytes(small_fig, "png")


def test_pdf_has_provenance(small_fig, tmp_path):
    data = save_figure(small_fig, tmp_path / "f.pdf").read_bytes()
    assert data.startswith(b"%PDF") and SHA.encode() in data


def test_bad_suffix_writes_nothing(small_fig, tmp_path):
    with pytest.raises(KesbrdfError, match=r"f.jpg: expected a figure file ending in .png, .svg, .pdf, got '.jpg'"):
        save_figure(small_fig, tmp_path / "f.jpg")
    assert list(tmp_path.iterdir()) == []


def test_read_png_text_rejects_other_data():
    with pytest.raises(KesbrdfError, match="expected PNG data"):
        read_png_text(b"GIF89a....")


def test_provenance_record(satin_model, satin_measurement, satin_ref):
    rec = provenance(satin_model, satin_measurement, satin_ref, figure="x", lights=np.array([[30.0, 90.0]]))
    assert rec["kesbrdf_version"] == __version__
    assert rec["input_sha256"] == satin_model.input_info.get("sha256")
    assert rec["inputs"]["measurement"]["sha256"] == satin_measurement.sha256
    assert rec["parameters"] == {"figure": "x", "lights": [[30.0, 90.0]]}
    assert rec["model_parameters"]["orientations"] == 4
    assert rec["inputs"]["reference"].startswith("AnisotropicWard(alpha_x=0.08")
    json.dumps(rec)  # plain JSON
    only_meas = provenance(measurement=satin_measurement)
    assert only_meas["input_sha256"] == satin_measurement.sha256


def test_describe_has_no_address():
    class Ref:
        def __init__(self):
            self.alpha = np.float64(0.5)
            self._hidden = 1

    assert describe(Ref()) == "Ref(alpha=0.5)"
