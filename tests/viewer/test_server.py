"""The viewer's HTTP server: model listing, limits, path traversal, bad input."""

from __future__ import annotations

import http.client
import json
import os
from pathlib import Path

import pytest

from kesbrdf.cli.main import main as cli_main
from kesbrdf.measure.demo_data import embedded_measurement
from kesbrdf.io.measurement_csv import read_measurement
from kesbrdf.models.kes import fit
from kesbrdf.viewer.server import STATIC_DIR, make_server

#: Upload limit of the servers under test: small, so oversize bodies are cheap to send.
LIMIT = 64 * 1024
#: Marker in a file next to (outside) the static folder; it must never be served.
SECRET = "kesbrdf-viewer-test-secret-7f3a"
#: Seconds a test waits for the server; generous for a shared, loaded machine.
TIMEOUT = 30


@pytest.fixture(scope="module")
def model_file(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("models")
    path = folder / "satin.kes.json"
    fit(read_measurement(embedded_measurement())).save(path)
    return path


@pytest.fixture
def site(tmp_path, model_file):
    """A served folder with a small fake bundle, a secret beside it and a model folder."""
    root = tmp_path / "site"
    static = root / "static"
    (static / "assets").mkdir(parents=True)
    (static / "index.html").write_text("<!doctype html><title>kesbrdf</title>")
    (static / "assets" / "app.js").write_text("console.log('hi');")
    (root / "secret.txt").write_text(SECRET)
    (static / "link-out.txt").symlink_to(root / "secret.txt")
    (static / "assets" / "link-dir").symlink_to(root, target_is_directory=True)
    models = tmp_path / "models"
    models.mkdir()
    (models / "copy.kes.json").write_bytes(model_file.read_bytes())
    (models / "notes.txt").write_text("not a model")
    outside = tmp_path / "outside.kes.json"
    outside.write_bytes(model_file.read_bytes())
    (models / "escape.kes.json").symlink_to(outside)
    return {"static": static, "models": models}


@pytest.fixture
def server(site, model_file, run_server):
    return run_server(make_server(
        model_files=[model_file],
        model_dirs=[site["models"]],
        port=0,
        static_dir=site["static"],
        max_upload_bytes=LIMIT,
    ))


def request(srv, method, path, body=None, headers=None):
    host, port = srv.server_address[:2]
    conn = http.client.HTTPConnection(host, port, timeout=TIMEOUT)
    try:
        conn.putrequest(method, path, skip_accept_encoding=True, skip_host="Host" in (headers or {}))
        for k, v in (headers or {}).items():
            conn.putheader(k, v)
        if body is not None and "Content-Length" not in (headers or {}):
            conn.putheader("Content-Length", str(len(body)))
        conn.endheaders()
        if body is not None:
            try:
                conn.send(body)
            except (BrokenPipeError, ConnectionResetError):
                pass  # the server may refuse and close before reading everything
        resp = conn.getresponse()
        return resp.status, resp.getheader("Content-Type"), resp.read()
    finally:
        conn.close()


def get_json(srv, path):
    status, ctype, data = request(srv, "GET", path)
    assert ctype == "application/json"
    return status, json.loads(data)


def test_models_lists_model_files_and_folder_models_only(server):
    status, doc = get_json(server, "/api/models")
    assert status == 200
    names = [m["name"] for m in doc["models"]]
    assert names[0] == "satin.kes.json"
    assert "copy.kes.json" in names
    # not models, or symlinks leading out of the model folder, are not listed
    assert "notes.txt" not in names
    assert "escape.kes.json" not in names and "outside.kes.json" not in names


def test_config_opens_the_given_model_first(server):
    status, doc = get_json(server, "/api/config")
    assert status == 200
    assert doc["initial"] == "f0"
    assert doc["max_upload_bytes"] == LIMIT


def test_model_returns_the_model_file_json(server, model_file):
    status, doc = get_json(server, "/api/model/f0")
    assert status == 200
    assert doc["name"] == "satin.kes.json"
    assert doc["model"] == json.loads(model_file.read_text())
    # the model's recorded input file is found unchanged, so it comes along
    assert doc["measurement"]["values"]["shape"] == [116, 3]


def test_a_changed_input_file_is_not_paired_with_the_model(tmp_path):
    from kesbrdf.viewer.server import find_input_measurement

    csv = tmp_path / "meas.csv"
    csv.write_bytes(embedded_measurement().read_bytes())
    fit(read_measurement(csv)).save(tmp_path / "m.kes.json")
    doc = json.loads((tmp_path / "m.kes.json").read_text())
    assert find_input_measurement(tmp_path / "m.kes.json", doc)["values"]["shape"] == [116, 3]
    csv.write_text(csv.read_text() + "\n")
    assert find_input_measurement(tmp_path / "m.kes.json", doc) is None


def test_explicit_measurement_is_served_with_the_first_model(model_file, tmp_path):
    srv = make_server(model_files=[model_file], port=0, measurement=embedded_measurement())
    try:
        entry = srv.store.get("f0")
        assert entry.measurement["channels"] == ["R", "G", "B"]
    finally:
        srv.server_close()


@pytest.mark.parametrize("ident", ["f99", "..%2Fsatin.kes.json", "%2Fetc%2Fpasswd", "u1"])
def test_unknown_model_id_is_404_with_json_error(server, ident):
    status, doc = get_json(server, f"/api/model/{ident}")
    assert status == 404
    assert "no model with id" in doc["error"]


def test_static_files_are_served(server):
    status, ctype, data = request(server, "GET", "/")
    assert status == 200 and ctype.startswith("text/html") and b"kesbrdf" in data
    status, ctype, data = request(server, "GET", "/assets/app.js")
    assert status == 200 and ctype.startswith("text/javascript")


@pytest.mark.parametrize(
    "path",
    [
        "/../secret.txt",
        "/assets/../../secret.txt",
        "/%2e%2e/secret.txt",
        "/%2E%2E%2Fsecret.txt",
        "/assets/..%2f..%2fsecret.txt",
        "/assets/%252e%252e/%252e%252e/secret.txt",
        "/..%5csecret.txt",
        "/..\\secret.txt",
        "//etc/passwd",
        "/%2fetc%2fpasswd",
        "/etc/passwd",
        "/index.html%00.txt",
        "/link-out.txt",
        "/assets/link-dir/secret.txt",
    ],
)
def test_no_path_outside_the_static_folder_is_reachable(server, path):
    status, ctype, data = request(server, "GET", path)
    assert status == 404
    assert SECRET.encode() not in data and b"root:" not in data
    assert json.loads(data)["error"].startswith("not found")


@pytest.mark.parametrize(
    "headers",
    [
        {"Host": "evil.example:80"},  # DNS rebinding: another site's name resolving to 127.0.0.1
        {"Origin": "http://evil.example"},  # a cross-site request from another page
    ],
)
def test_requests_from_other_sites_are_refused(server, headers):
    host, port = server.server_address[:2]
    headers = {"Host": f"{host}:{port}", **headers}
    status, _, data = request(server, "GET", "/api/models", headers=headers)
    assert status == 403
    status, _, data = request(server, "POST", "/api/fit?name=a.csv", b"x", headers=headers)
    assert status == 403
    assert get_json(server, "/api/config")[0] == 200


def test_same_origin_requests_are_served(server):
    host, port = server.server_address[:2]
    headers = {"Host": f"localhost:{port}", "Origin": f"http://localhost:{port}"}
    assert request(server, "GET", "/api/models", headers=headers)[0] == 200


def test_resolve_static_absolute_path_stays_inside(server, site):
    assert server.resolve_static("/" + str(site["static"].parent / "secret.txt")) is None
    assert server.resolve_static("/index.html") == (site["static"] / "index.html").resolve()


def test_upload_over_the_limit_is_refused_and_the_server_keeps_running(server):
    body = b"x" * (LIMIT + 1)
    status, _, data = request(server, "POST", "/api/fit?name=big.csv", body, {"Content-Type": "text/csv"})
    assert status == 413
    assert json.loads(data)["error"] == f"upload too large: {LIMIT + 1} bytes, limit {LIMIT} bytes"
    assert get_json(server, "/api/models")[0] == 200


def test_oversize_content_length_is_refused_before_reading_the_body(server):
    # announces 1 GB but sends nothing: the reply must come without waiting for the body
    status, _, data = request(server, "POST", "/api/fit", b"", {"Content-Length": str(10**9)})
    assert status == 413
    assert get_json(server, "/api/config")[0] == 200


def test_upload_without_content_length_is_refused(server):
    status, _, data = request(server, "POST", "/api/fit", None)
    assert status == 411
    assert "Content-Length" in json.loads(data)["error"]


def test_bad_csv_gives_the_cli_message_and_the_server_keeps_running(server, tmp_path, monkeypatch, capsys):
    lines = embedded_measurement().read_text().splitlines()
    header_at = next(i for i, line in enumerate(lines) if line.startswith("psi_deg"))
    row = lines[header_at + 3].split(",")
    row[3] = "oops"
    lines[header_at + 3] = ",".join(row)
    text = "\n".join(lines) + "\n"
    (tmp_path / "bad.csv").write_text(text)
    monkeypatch.chdir(tmp_path)
    assert cli_main(["fit", "bad.csv", "-o", "bad.kes.json"]) == 2
    cli_message = capsys.readouterr().err.strip().removeprefix("kesbrdf: error: ")
    assert cli_message.startswith(f"bad.csv:{header_at + 4}:")

    status, _, data = request(server, "POST", "/api/fit?name=bad.csv", text.encode())
    assert status == 400
    assert json.loads(data) == {"error": cli_message}
    assert get_json(server, "/api/models")[0] == 200


@pytest.mark.parametrize("body", [b"", b"\xff\xfe\x00garbage", b"psi_deg,theta_i_deg\n1,2\n"])
def test_malformed_uploads_are_400_with_one_line_errors(server, body):
    status, _, data = request(server, "POST", "/api/fit?name=x.csv", body)
    assert status == 400
    message = json.loads(data)["error"]
    assert message and "\n" not in message and "kesbrdf-view-" not in message
    assert get_json(server, "/api/config")[0] == 200


def test_upload_name_cannot_escape_the_temporary_folder(server):
    body = embedded_measurement().read_bytes()
    status, _, data = request(server, "POST", "/api/fit?name=..%2F..%2Fevil.csv", body)
    assert status == 200
    doc = json.loads(data)
    assert doc["name"] == "evil.csv"


def test_good_csv_is_fitted_listed_and_loadable(server):
    body = embedded_measurement().read_bytes()
    status, _, data = request(server, "POST", "/api/fit?name=satin.csv", body, {"Content-Type": "text/csv"})
    assert status == 200
    doc = json.loads(data)
    assert doc["model"]["format"] == "kesbrdf-model"
    assert doc["model"]["channels"] == ["R", "G", "B"]
    assert doc["model"]["input"]["name"] == "satin.csv"
    assert doc["measurement"]["values"]["shape"] == [116, 3]
    assert "ward" in doc["measurement"]["metadata"]["generator"]
    status, listing = get_json(server, "/api/models")
    assert {"id": doc["id"], "name": "satin.csv", "kind": "upload", "has_measurement": True} in listing["models"]
    status, again = get_json(server, f"/api/model/{doc['id']}")
    assert status == 200 and again["model"] == doc["model"]


def test_broken_model_file_is_an_error_not_a_crash(server, site):
    (site["models"] / "broken.kes.json").write_text("{not json")
    _, listing = get_json(server, "/api/models")
    ident = next(m["id"] for m in listing["models"] if m["name"] == "broken.kes.json")
    status, doc = get_json(server, f"/api/model/{ident}")
    assert status == 422
    assert "broken.kes.json:1:" in doc["error"]
    assert get_json(server, "/api/models")[0] == 200


def test_view_cli_reports_a_missing_input_like_every_command(tmp_path, capsys):
    assert cli_main(["view", str(tmp_path / "nope.kes.json"), "--no-browser"]) == 2
    assert "nope.kes.json" in capsys.readouterr().err


def test_view_cli_reports_a_non_model_file(tmp_path, capsys):
    (tmp_path / "x.kes.json").write_text('{"format": "something-else"}')
    assert cli_main(["view", str(tmp_path / "x.kes.json"), "--no-browser", "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("kesbrdf: error: ") and "kesbrdf-model" in err  # the model loader's message


def test_shipped_bundle_is_complete():
    index = STATIC_DIR / "index.html"
    assert index.is_file(), "run `make viewer-bundle`"
    html = index.read_text()
    import re

    refs = re.findall(r'(?:src|href)="\./([^"]+)"', html)
    assert refs, "index.html references no assets"
    for ref in refs:
        assert (STATIC_DIR / ref).is_file(), ref


def test_view_cli_serves_and_prints_the_url(model_file):
    import subprocess
    import sys

    src = Path(__file__).resolve().parents[2] / "src"
    env = {**os.environ, "PYTHONPATH": str(src)}
    cmd = [sys.executable, "-m", "kesbrdf.cli.main", "view", str(model_file), "--port", "0", "--no-browser"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline()
        assert line.startswith("kesbrdf viewer: http://127.0.0.1:"), line
        url = line.split()[2]
        port = int(url.rstrip("/").rsplit(":", 1)[1])
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=TIMEOUT)
        conn.request("GET", "/api/models")
        resp = conn.getresponse()
        assert resp.status == 200
        assert json.loads(resp.read())["models"][0]["name"] == "satin.kes.json"
        conn.close()
    finally:
        proc.terminate()
        proc.wait(TIMEOUT)
        proc.stdout.close()
        proc.stderr.close()


def test_unknown_fallback_is_refused(server):
    body = embedded_measurement().read_bytes()
    status, _, data = request(server, "POST", "/api/fit?name=s.csv&fallback=magic", body)
    assert status == 400
    assert json.loads(data)["error"] == "fallback: expected one of error, log, got 'magic'"
