"""Write errors are one line, exit 2, and leave nothing behind (project issue 16, item 6).

For each class of system error (disk full, quota, file too large, failing device,
read-only file system, permission denied) injected into the output folder with
:func:`faults.failing_writes`, every writing command tested — ``fit``, ``export``
(a text and a binary format), ``eval``, ``simulate``, ``validate --json`` — must
print exactly one line on stderr that names the output path and the cause in words,
exit with 2, and leave the output folder as it was (no temporary, no half file).
Real cases need no injection: a 300-character file name, ``-o`` below an existing
file, and ``-o`` below missing folders (docs/decisions.md, "Outputs and write errors").
"""

from __future__ import annotations

import errno
import os

import pytest
from faults import CASES, failing_writes, listing

from kesbrdf.cli.main import main

#: A name longer than any common file system allows (ext4, XFS, tmpfs, APFS, NTFS: 255).
LONG_NAME = "a" * 300


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A small measurement, a kes model fitted from it and a pairs file (made once)."""
    d = tmp_path_factory.mktemp("inputs")
    meas, model, pairs = d / "meas.csv", d / "model.kes.json", d / "pairs.csv"
    assert main(["simulate", "--reference", "ward", "-o", str(meas)]) == 0
    assert main(["fit", str(meas), "--kind", "kes", "-o", str(model)]) == 0
    pairs.write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\n60,180,30,0\n30,90,45,200\n")
    return {"meas": meas, "model": model, "pairs": pairs}


def commands(inputs, out):
    """Command name -> (argv, the output file it writes) for an output folder ``out``."""
    return {
        "fit": (["fit", str(inputs["meas"]), "--kind", "kes", "-o", str(out / "m.kes.json")], out / "m.kes.json"),
        "export-gltf": (["export", str(inputs["model"]), "--format", "gltf", "-o", str(out / "m.gltf"),
                         "-O", f"fit_grid={SMALL_GRID}", "-O", f"error_grid={SMALL_GRID}"], out / "m.gltf"),
        "export-brdf-explorer": (["export", str(inputs["model"]), "--format", "brdf-explorer",
                                  "-o", str(out / "m.brdf")], out / "m.brdf"),
        "export-rgl-bsdf": (["export", str(inputs["model"]), "--format", "rgl-bsdf", "-o", str(out / "m.bsdf"),
                             "-O", "n_theta_i=3", "-O", "n_phi_i=5", "-O", "n=16", "-O", "check=false"], out / "m.bsdf"),
        "eval": (["eval", str(inputs["model"]), "--pairs", str(inputs["pairs"]), "-o", str(out / "f.csv")],
                 out / "f.csv"),
        "simulate": (["simulate", "--reference", "ward", "-o", str(out / "s.csv")], out / "s.csv"),
        "validate": (["validate", str(inputs["model"]), str(inputs["meas"]), "--json", str(out / "v.json")],
                     out / "v.json"),
    }


#: Commands run for every error class: fit, a text and a binary export, and three more
#: writers (the glTF export's analytic fit takes seconds: it runs for the report's case,
#: ENOSPC, and for the real-path cases below).
COMMANDS = ("fit", "export-brdf-explorer", "export-rgl-bsdf", "eval", "simulate", "validate")
#: The analytic fit's grids for the glTF export (the tests check errors, not fit quality).
SMALL_GRID = "[[4, 8], [6, 12]]"


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("kesbrdf: error:")]
    assert len(lines) == 1, err
    assert "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("command,case", [(c, e) for c in COMMANDS for e in sorted(CASES)]
                         + [("export-gltf", "ENOSPC")])
def test_system_write_errors_are_one_line_and_leave_nothing(tmp_path, monkeypatch, capsys, inputs, command, case):
    code, at, words = CASES[case]
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("an unrelated file")
    argv, target = commands(inputs, out)[command]
    before = listing(out)
    capsys.readouterr()
    failing_writes(monkeypatch, out, code, at=at)
    rc = main(argv)
    monkeypatch.undo()
    line = _one_error_line(capsys)
    assert rc == 2
    assert str(target) in line and words in line, line
    assert listing(out) == before  # no temporary, no half file, no target


@pytest.mark.parametrize("command", ("fit", "export-rgl-bsdf"))
def test_a_failed_write_removes_the_folder_it_created(tmp_path, monkeypatch, capsys, inputs, command):
    """`-o out/new/x` with `out/new` missing: the folder made for the output goes again on failure."""
    out = tmp_path / "out"
    out.mkdir()
    argv, target = commands(inputs, out / "new")[command]
    failing_writes(monkeypatch, out, errno.ENOSPC, at="write")
    rc = main(argv)
    monkeypatch.undo()
    assert rc == 2 and "disk full" in _one_error_line(capsys)
    assert listing(out) == []


@pytest.mark.parametrize("command", COMMANDS + ("export-gltf",))
def test_a_300_character_name_is_one_line(tmp_path, capsys, inputs, command):
    argv, target = commands(inputs, tmp_path)[command]
    long_target = target.with_name(LONG_NAME + "".join(target.suffixes))
    argv = [str(long_target) if a == str(target) else a for a in argv]
    before = listing(tmp_path)
    assert main(argv) == 2
    line = _one_error_line(capsys)
    assert "file name too long" in line and LONG_NAME in line
    assert listing(tmp_path) == before


@pytest.mark.parametrize("command", ("fit", "eval"))
def test_a_long_name_that_fits_is_written(tmp_path, inputs, command):
    """A 240-byte name is legal; only the temporary's longer name would not be (it is shortened)."""
    argv, target = commands(inputs, tmp_path)[command]
    long_target = target.with_name("b" * (240 - len("".join(target.suffixes))) + "".join(target.suffixes))
    argv = [str(long_target) if a == str(target) else a for a in argv]
    assert main(argv) == 0
    assert long_target.is_file() and [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.parametrize("command", COMMANDS + ("export-gltf",))
def test_output_below_an_existing_file_is_one_line(tmp_path, capsys, inputs, command):
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    argv, target = commands(inputs, blocker)[command]  # -o afile/NAME
    assert main(argv) == 2
    line = _one_error_line(capsys)
    assert str(blocker) in line and "is a file" in line, line
    assert listing(tmp_path) == ["afile"] and blocker.read_text() == "x"


@pytest.mark.parametrize("command", COMMANDS)
def test_output_below_missing_folders_is_refused_naming_the_first(tmp_path, capsys, inputs, command):
    argv, target = commands(inputs, tmp_path / "typo" / "deeper")[command]
    assert main(argv) == 2
    line = _one_error_line(capsys)
    assert f"folder {tmp_path / 'typo'} does not exist" in line, line
    assert listing(tmp_path) == []


@pytest.mark.parametrize("command", ("fit", "export-brdf-explorer", "eval"))
def test_the_output_folder_itself_is_created(tmp_path, inputs, command):
    """One missing level (`-o out/model.kes.json` in a fresh checkout) is created."""
    argv, target = commands(inputs, tmp_path / "out")[command]
    assert main(argv) == 0
    assert target.is_file()


def test_folder_outputs_follow_the_same_rule(tmp_path, capsys):
    """`simulate --library N -o DIR` (a folder output): DIR and its parent may be made, no more."""
    assert main(["simulate", "--library", "1", "--broken", "0", "-o", str(tmp_path / "a" / "b" / "lib")]) == 2
    assert f"folder {tmp_path / 'a'} does not exist" in _one_error_line(capsys)
    assert listing(tmp_path) == []
    assert main(["simulate", "--library", "1", "--broken", "0", "-o", str(tmp_path / "a" / "lib")]) == 0
    assert (tmp_path / "a" / "lib").is_dir()


def test_oserror_outside_atomic_writes_is_one_line(tmp_path, monkeypatch, capsys, inputs):
    """The CLI's last line of defence: any OSError becomes one line with the cause in words."""
    import kesbrdf.cli.fit as fit_cli

    def broken(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp_path / "x"))

    monkeypatch.setattr(fit_cli, "_options", broken)
    assert main(["fit", str(inputs["meas"]), "-o", str(tmp_path / "m.kes.json")]) == 2
    assert _one_error_line(capsys) == f"kesbrdf: error: {tmp_path / 'x'}: disk full (no space left on device)"
