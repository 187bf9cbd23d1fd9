"""Viewer benchmarks: the `kesbrdf view` server's API latency, and the browser preview's
frame time when the web suite has measured it.

``run()`` returns named numbers; ``benchmarks/run.py`` collects every ``bench_*.py``.
Run alone with ``PYTHONPATH=src python benchmarks/bench_viewer.py``.

The preview frame time (512×512, software WebGL on SwiftShader) needs Chromium, so it
is measured by ``npm test`` in ``viewer/`` (written to viewer/test-output/frame-time.json)
and only copied here when that file exists.
"""

from __future__ import annotations

import http.client
import json
import tempfile
import threading
import time
from pathlib import Path


from _timing import best_of

ROOT = Path(__file__).resolve().parent.parent




def run() -> dict:
    from kesbrdf.measure.demo_data import embedded_measurement
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.models.kes import fit
    from kesbrdf.viewer.server import make_server

    results: dict = {}
    csv = embedded_measurement().read_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        model_path = Path(tmp) / "satin.kes.json"
        fit(read_measurement(embedded_measurement())).save(model_path)
        server = make_server(model_files=[model_path], port=0)
        thread = threading.Thread(target=server.serve_forever, daemon=True)
        thread.start()
        host, port = server.server_address[:2]

        def call(method, path, body=None):
            conn = http.client.HTTPConnection(host, port, timeout=60)
            conn.request(method, path, body=body)
            resp = conn.getresponse()
            data = resp.read()
            conn.close()
            assert resp.status == 200, data[:200]
            return data

        size = len(call("GET", "/api/model/f0"))
        results["api_model_ms"] = 1e3 * best_of(lambda: call("GET", "/api/model/f0"), 5)
        results["api_model_bytes"] = size
        # as in the browser: the page loads, then the user uploads; the server starts a
        # warm fit process on page load and after each fit, so give it time to start
        call("GET", "/")
        fit_ms = []
        for _ in range(3):
            time.sleep(3.0)
            t0 = time.perf_counter()
            call("POST", "/api/fit?name=s.csv", csv)
            fit_ms.append(1e3 * (time.perf_counter() - t0))
        results["api_fit_116_samples_ms"] = min(fit_ms)
        results["static_bundle_ms"] = 1e3 * best_of(lambda: call("GET", "/assets/index.js"), 5)
        server.shutdown()
        server.server_close()
    frame = ROOT / "viewer" / "test-output" / "frame-time.json"
    if frame.exists():
        measured = json.loads(frame.read_text())
        for name in ("sphere", "swatch", "cloth"):
            if name in measured:
                results[f"preview_{name}_512_ms_per_frame"] = measured[name]
    return results


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))
