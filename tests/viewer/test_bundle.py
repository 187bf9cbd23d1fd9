"""The shipped viewer bundle keeps the browser-test hooks in their own chunk."""

from kesbrdf.viewer.server import STATIC_DIR

#: Names only the test hooks (viewer/src/testhooks.ts) define.
HOOK_NAMES = ("previewProbe", "canvasStats", "benchPreview")


def test_test_hooks_are_a_separate_chunk_not_in_the_page_bundle():
    page = (STATIC_DIR / "assets" / "index.js").read_text(encoding="utf-8")
    hooks = (STATIC_DIR / "assets" / "testhooks.js").read_text(encoding="utf-8")
    for name in HOOK_NAMES:
        assert name not in page, f"{name} leaked into the page bundle"
        assert name in hooks
    assert "testhooks" in page  # loaded on demand (?testhooks), not statically
