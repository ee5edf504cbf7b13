"""The front door: one namespace, a missing stage is an error, never a silent success, and an
error is one line on stderr."""

from __future__ import annotations

import subprocess
import sys

import demcal.cli


def test_a_missing_stage_is_an_error_naming_it(monkeypatch, capsys):
    monkeypatch.setattr(demcal.cli, "STAGE_CLIS", demcal.cli.STAGE_CLIS + ("demcal.no_such_stage",))
    assert demcal.cli.main(["audit", "anywhere"]) == demcal.cli.EXIT_FAILURE
    err = capsys.readouterr().err
    assert "demcal.no_such_stage" in err and "reinstall" in err


def test_an_error_quoting_text_with_line_breaks_is_one_line(tmp_path, capsys):
    folder = tmp_path / "campaign\ndemcal export: wrote everything\r\u2028\x1b[2J"
    folder.mkdir()
    assert demcal.cli.main(["export", str(folder)]) == demcal.cli.EXIT_INPUT
    err = capsys.readouterr().err
    assert err.endswith("\n") and err[:-1].isprintable()         # one line, no control character
    assert err.startswith("demcal export: error: ") and "holds no results.json" in err
    assert "wrote everything" in err


def test_nothing_generic_is_importable_from_outside_the_repository(tmp_path):
    # run where the repository's folders are not on the path: only demcal.* is installed
    code = ("import importlib.util as u; import demcal.measure, demcal.report.audit; "
            "print([n for n in ('measure', 'simulate', 'analyse', 'report') if u.find_spec(n)])")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_every_module_imports_its_stages_through_demcal():
    import demcal.analyse.campaign  # noqa: F401  (imports every stage)
    import demcal.calibrate  # noqa: F401
    import demcal.report.render  # noqa: F401

    generic = [name for name in sys.modules if name.split(".")[0] in ("measure", "simulate", "analyse", "report")]
    assert generic == []
