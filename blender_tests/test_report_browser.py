"""report.html in a real browser: headless Chromium loads a report of a small real run
(scripts/gi_compare.py on cornell at 24 px) with ``#selftest``; the page's own check sorts the
summary table and flips and slides a viewer, and writes its outcome into ``<body>``.

Only the Python standard library drives the browser (``--dump-dom``); console messages are
read from Chromium's ``--enable-logging=stderr`` output. Skipped when no Chromium is
installed (scripts/test.sh installs it)."""
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "scripts" / "gi_compare.py"
BROWSER = next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome")
                if shutil.which(b)), None)

pytestmark = pytest.mark.skipif(BROWSER is None, reason="no Chromium (scripts/test.sh installs it)")

# the statements whose removal must make the self-check fail
FLIP = 'v.setAttribute("data-show", v.getAttribute("data-show") === "a" ? "b" : "a");'
SORT = "rows.forEach(function (r) { tb.appendChild(r); });"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """gi_compare's output of SSR, SSDO and DIRECT on cornell (24 px, Cycles only)."""
    pytest.importorskip("bpy")
    import importlib.util
    tmp = tmp_path_factory.mktemp("report_browser")
    out = tmp / "out"
    spec = importlib.util.spec_from_file_location("gi_compare_script", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("XDG_CACHE_HOME", str(tmp / "cache"))
        mp.setattr(sys, "argv", [str(SCRIPT), "cornell", "--techniques", "SSR,SSDO,DIRECT", "--res", "24",
                                 "--ref-spp", "16", "--frames", "1", "--quality", "0", "--reference", "full",
                                 "--baselines", "none", "--cycles-curve", "1,2,4",
                                 "--cache", str(tmp / "refs"), "--out", str(out)])
        mod.main()
    return out


def _browse(path: Path, tmp: Path, fragment: str = "#selftest") -> tuple[str, str]:
    """(the DOM after load, Chromium's stderr) of a local page."""
    p = subprocess.run([BROWSER, "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run",
                        f"--user-data-dir={tmp / 'chromium'}", "--enable-logging=stderr", "--v=0",
                        "--dump-dom", path.resolve().as_uri() + fragment],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-3000:]
    return p.stdout, p.stderr


def _console(stderr: str) -> list[str]:
    """Console messages (errors, uncaught exceptions, logs) Chromium wrote to its log."""
    return [ln for ln in stderr.splitlines() if ":CONSOLE" in ln]


def _body_attrs(dom: str) -> dict:
    m = re.search(r"<body([^>]*)>", dom)
    assert m, dom[:500]
    return dict(re.findall(r'([\w-]+)="([^"]*)"', m.group(1)))


def _summary_rows(dom: str) -> list[str]:
    m = re.search(r'<table id="summary">.*?<tbody>(.*?)</tbody>', dom, re.S)
    assert m, "no summary table"
    return re.findall(r"<tr\b.*?</tr>", m.group(1), re.S)


def test_report_in_browser(run_dir, tmp_path):
    res = json.loads((run_dir / "results.json").read_text())
    entries = {e["technique"]: e for e in res["entries"] if e["reference"] == "full"}
    assert set(entries) == {"SSR", "SSDO", "DIRECT"}
    dom, err = _browse(run_dir / "report.html", tmp_path)
    assert _console(err) == []
    attrs = _body_attrs(dom)
    assert "data-errors" not in attrs, attrs["data-errors"]
    assert attrs.get("data-selftest") == "ok", attrs.get("data-selftest")
    # one row per distinct image: cornell has no glossy surface, so SSR skips its reflection
    # passes and gives DIRECT's image; the two share a row that says why
    rows = _summary_rows(dom)
    distinct = {e["image_sha256"] for e in entries.values()}
    assert entries["SSR"]["image_sha256"] == entries["DIRECT"]["image_sha256"] != entries["SSDO"]["image_sha256"]
    assert int(attrs["data-summary-rows"]) == len(rows) == len(distinct) == 2
    folded = [r for r in rows if "SSR q0" in r and "DIRECT q0" in r]
    assert len(folded) == 1 and "no glossy surface in view" in folded[0], rows
    # the self-check left the table sorted by relMSE, descending
    rel = [float(re.findall(r'<td data-v="([^"]*)"', r)[0]) for r in rows]  # the first numeric column
    assert rel == sorted(rel, reverse=True)
    # the device, and missing baselines shown as dashes
    assert "llvmpipe" not in res["run"]["gl_renderer"].lower() or "CPU-emulated times" in dom
    assert res["run"]["gl_renderer"] in dom
    assert dom.count("\u2014</td>") >= 2 * len(rows)  # no Cycles + OIDN or EEVEE in this run


@pytest.mark.parametrize("statement, failure", [(FLIP, "flip did not change the displayed image"),
                                                (SORT, "relMSE not")], ids=["flip", "sort"])
def test_selftest_catches_a_broken_page(run_dir, tmp_path, statement, failure):
    """The same report with the viewer's flip (or the table's re-ordering) removed: the
    self-check reports the failure instead of "ok"."""
    page = (run_dir / "report.html").read_text()
    assert page.count(statement) == 1
    broken = tmp_path / "broken.html"
    broken.write_text(page.replace(statement, ""))
    dom, err = _browse(broken, tmp_path)
    assert _console(err) == []
    outcome = _body_attrs(dom).get("data-selftest", "")
    assert outcome.startswith("fail") and failure in outcome, outcome


def test_index_in_browser(run_dir, tmp_path):
    """The index of a sweep over scenes (report.write_index, as gi_compare writes it for several
    scenes): the run above as one scene and a failed scene; it loads without console messages,
    links the scene's report and shows the failure."""
    import shutil
    from gi_preview.compare import report
    site = tmp_path / "sweep"
    shutil.copytree(run_dir, site / "cornell")
    res = json.loads((run_dir / "results.json").read_text())
    rows = [{"technique": e["technique"], "quality": e["quality"], "denoiser": e.get("denoiser"),
             "relmse": e["relmse"], "flip": e["flip"], "time_ms": e["time_ms"]}
            for e in res["entries"] if e["reference"] == "full"]
    summary = {"wall_s": 1.0, "workers": 2, "failed": ["gone"], "tasks_run": [], "tasks_skipped": 0,
               "scenes": [{"label": "cornell", "report": "cornell/report.html", "error": None,
                           "resolution": res["resolution"], "reference_ms": res["reference"]["time_ms"],
                           "reference_spp": 16, "rows": rows},
                          {"label": "gone", "report": None, "error": "gi_compare: no such file gone.blend",
                           "rows": []}]}
    report.write_index(str(site / "index.html"), summary)
    dom, err = _browse(site / "index.html", tmp_path, fragment="")
    assert _console(err) == []
    links = re.findall(r'<a href="([^"]+)"', dom)
    assert links == ["cornell/report.html"] and (site / links[0]).exists()
    assert "failed: gi_compare: no such file gone.blend" in dom
    assert dom.count("<circle") >= len(rows)  # the chart across scenes: a dot per technique
