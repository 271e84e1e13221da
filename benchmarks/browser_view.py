"""The live view (`jb.explore`) as a browser shows it: JupyterLab in headless Chromium, driven by selenium.

For each scene a notebook cell makes the view (`ex = jb.explore(scene)`, its values recorded before any browser saw
it) and shows it; once the browser has rendered every view, a cell reads back what the kernel holds. Checked per
view: every slider and every key number is the call's (opening a view changes nothing), the browser's readouts show
the start values, no horizontal scrollbar at a 1000 px wide window, the legends' text height on screen. On the
four-bar, the "tune PID" button is clicked in the browser: the three gains must reach the kernel and the browser's
readouts as `jb.tune_pid` gives them headless from the same start, and its message must show. Screenshots of each
view are written beside the JSON (`browser_view_<scene>.png`).

Needs what the project does not (the `browser` extra and two system packages):
`pip install 'jaxbelt[browser]'` (selenium, jupyterlab) and `apt-get install chromium chromium-driver`. Without them
the script says what is missing and exits 0 (it is a check to run by hand, not part of a quick CI run).

Run: `python benchmarks/browser_view.py [--quick]` (`--quick`: the four-bar and the shaping view only, 5 tune
steps). Writes `browser_view.json` (and the PNGs) to `results/` (`results/quick/` with `--quick`).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

SCENES = ("startup", "fourbar", "shaping", "spans", "nonlinear", "axis")
QUICK_SCENES = ("fourbar", "shaping")
WINDOW = (1000, 1400)  # px: the window's width the layout must fit


def missing() -> list[str]:
    """What this machine lacks to run the check."""
    out = [m for m in ("selenium", "jupyterlab") if importlib.util.find_spec(m) is None]
    out += [
        f"{b} (apt-get install chromium chromium-driver)" for b in ("chromium", "chromedriver") if not shutil.which(b)
    ]
    return out


def _cell(source: str) -> dict:
    return {"cell_type": "code", "metadata": {}, "execution_count": None, "outputs": [], "source": source}


def notebook(scenes, tune_steps: int) -> dict:
    """The notebook: one cell per view, then the read-back cells (their output lines start with RESULT / TUNE)."""
    cells = [
        _cell(
            "import json, time\nimport jax\nimport numpy as np\n\njax.config.update('jax_enable_x64', True)\n"
            "import jaxbelt as jb\n\nprint('jaxbelt from', jb.__file__)"
        )
    ]
    for s in scenes:
        opts = f", tune_steps={tune_steps}" if s == "fourbar" else ""
        cells.append(
            _cell(
                f"ex_{s} = jb.explore({s!r}{opts})\nref_{s} = (dict(ex_{s}.slider_values), dict(ex_{s}.values))\nex_{s}"
            )
        )
    scene_list = ", ".join(repr(s) for s in scenes)
    cells.append(
        _cell(
            "def same(a, b):\n"
            "    try:\n"
            "        return bool(np.array_equal(np.asarray(a), np.asarray(b)))\n"
            "    except Exception:\n"
            "        return a == b\n"
            "out = {}\n"
            f"for s in ({scene_list},):\n"
            "    ex, (sl, vals) = globals()['ex_' + s], globals()['ref_' + s]\n"
            "    ex.wait(300)\n"
            "    out[s] = dict(\n"
            "        sliders=ex.slider_values, start=sl, error=ex.error, computed=ex.stats['computed'],\n"
            "        sliders_changed={k: [sl[k], v] for k, v in ex.slider_values.items() if v != sl[k]},\n"
            "        values_changed=[k for k in vals if not same(vals[k], ex.values.get(k))],\n"
            "        values={k: (v if isinstance(v, str) else np.asarray(v, dtype=float).tolist()) for k, v in ex.values.items()},\n"
            "    )\n"
            "print('RESULT ' + json.dumps(out))"
        )
    )
    if "fourbar" in scenes:
        cells.append(
            _cell(
                "ex = ex_fourbar\n"
                "time.sleep(0.5)\n"
                "ex.wait(600)\n"
                "start = ex.scene.pid_of(ref_fourbar[0])\n"
                f"res = jb.tune_pid(jb.FourBarDrive(), start, 0.375, 0.5, steps={tune_steps}, progress=False)\n"
                "ref = dict(kp=float(res.pid.kp), ki=float(res.pid.ki), kd=float(res.pid.kd))\n"
                "print('TUNE ' + json.dumps(dict(sliders=ex.slider_values, headless=ref, status=ex._status.value,\n"
                "      chi=ex.values.get('chi'), error=ex.error)))"
            )
        )
    return {
        "cells": cells,
        "metadata": {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}},
        "nbformat": 4,
        "nbformat_minor": 5,
    }


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_lab(folder: Path, port: int) -> subprocess.Popen:
    """JupyterLab on `folder`, no token, its kernels importing this checkout's jaxbelt."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    # the lab extensions of the base environment (ipywidgets' jupyterlab_widgets) where this runs in a venv
    env["JUPYTER_PATH"] = os.pathsep.join(
        p for p in (env.get("JUPYTER_PATH"), str(Path(sys.base_prefix) / "share" / "jupyter")) if p
    )
    cmd = [sys.executable, "-m", "jupyterlab", "--no-browser", f"--port={port}", "--ServerApp.token=",
           "--ServerApp.password=", "--ServerApp.disable_check_xsrf=True", "--allow-root", f"--notebook-dir={folder}"]  # fmt: skip
    log = open(folder / "lab.log", "w")
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, cwd=folder)
    deadline = time.time() + 90
    while time.time() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1):
                return proc
        except OSError:
            time.sleep(0.5)
    proc.terminate()
    raise RuntimeError(f"JupyterLab did not start in 90 s; see {folder / 'lab.log'}")


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium") or "chromium"
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu"):
        opts.add_argument(a)
    opts.add_argument(f"--window-size={WINDOW[0]},{WINDOW[1]}")
    return webdriver.Chrome(service=Service(shutil.which("chromedriver") or "chromedriver"), options=opts)


def log(*a) -> None:
    print(*a, flush=True)


_SHOT: list = []  # (driver, folder) for a screenshot of the page when a wait times out


def _wait(fn, timeout: float, what: str, poll: float = 0.5):
    log(f"browser_view: waiting for {what}")
    deadline = time.time() + timeout
    while time.time() < deadline:
        if _SHOT and "Traceback" in _SHOT[0][0].find_element("css selector", ".jp-Notebook").text:
            _SHOT[0][0].save_screenshot(str(_SHOT[0][1] / "browser_view_error.png"))
            raise RuntimeError(f"browser_view: a cell failed while waiting for {what} (browser_view_error.png)")
        try:
            v = fn()
        except Exception:
            v = None
        if v:
            return v
        time.sleep(poll)
    if _SHOT:
        _SHOT[0][0].save_screenshot(str(_SHOT[0][1] / "browser_view_timeout.png"))
    raise TimeoutError(f"browser_view: waited {timeout:g} s for {what}")


def run_cell(driver, index: int) -> None:
    """Select code cell `index` and run it (command mode, Shift+Enter)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    cells = driver.find_elements("css selector", ".jp-Notebook .jp-Cell")
    cells[index].find_element("css selector", ".jp-InputPrompt").click()
    ActionChains(driver).send_keys(Keys.ESCAPE).key_down(Keys.SHIFT).send_keys(Keys.ENTER).key_up(Keys.SHIFT).perform()


def output_text(driver, index: int) -> str:
    cells = driver.find_elements("css selector", ".jp-Notebook .jp-Cell")
    return "\n".join(e.text for e in cells[index].find_elements("css selector", ".jp-OutputArea-output"))


def cell_done(driver, index: int) -> bool:
    cells = driver.find_elements("css selector", ".jp-Notebook .jp-Cell")
    prompt = cells[index].find_element("css selector", ".jp-InputPrompt").text
    return bool(prompt) and "*" not in prompt and prompt.strip() not in ("[ ]:", "")


_LAYOUT_JS = """
const cell = arguments[0];
const out = cell.querySelector('.jp-OutputArea-output');
const img = out ? out.querySelector('img') : null;
const readouts = Array.from(cell.querySelectorAll('.widget-readout')).map(e => e.textContent.trim());
const labels = Array.from(cell.querySelectorAll('.widget-slider .widget-label')).map(e => e.textContent.trim());
const doc = document.scrollingElement || document.documentElement;
const wide = Array.from(document.querySelectorAll('.jp-OutputArea-output, .jp-WindowedPanel-outer, .jp-Notebook'))
  .filter(e => e.scrollWidth > e.clientWidth + 1).length;
return {readouts: readouts, labels: labels, out_width: out ? out.scrollWidth : null,
        out_client: out ? out.clientWidth : null, img_shown: img ? img.clientWidth : null,
        img_natural: img ? img.naturalWidth : null, overflowing: wide,
        page_scroll: doc.scrollWidth > doc.clientWidth + 1};
"""


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="the four-bar and shaping views only, 5 tune steps")
    args = p.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # a kill closes the browser and the server too
    lack = missing()
    if lack:
        print(f"browser_view: skipped, this machine lacks {', '.join(lack)} (pip install 'jaxbelt[browser]')")
        return 0
    from _common import results_dir, write_results

    scenes = QUICK_SCENES if args.quick else SCENES
    tune_steps = 5 if args.quick else 20
    out_dir = results_dir(args.quick)
    out_dir.mkdir(parents=True, exist_ok=True)
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="jaxbelt-browser-") as tmp:
        folder = Path(tmp)
        (folder / "view.ipynb").write_text(json.dumps(notebook(scenes, tune_steps)))
        port = _free_port()
        lab = start_lab(folder, port)
        driver = None
        try:
            driver = browser()
            driver.get(f"http://127.0.0.1:{port}/lab/tree/view.ipynb")
            _wait(lambda: len(driver.find_elements("css selector", ".jp-Notebook .jp-Cell")) >= len(scenes) + 2, 120,
                  "the notebook")  # fmt: skip
            _SHOT.append((driver, out_dir))
            time.sleep(2.0)
            for tab in driver.find_elements("css selector", ".jp-SideBar.jp-mod-left .lm-TabBar-tab.lm-mod-current"):
                tab.click()  # the file browser folds away: the notebook has the window's width
            rows, timings = [], {}
            run_cell(driver, 0)
            _wait(lambda: "jaxbelt from" in output_text(driver, 0), 180, "the import cell")
            print(output_text(driver, 0))
            layout = {}
            for i, s in enumerate(scenes, start=1):
                t = time.perf_counter()
                run_cell(driver, i)
                _wait(lambda i=i: driver.find_elements("css selector", ".jp-Notebook .jp-Cell")[i].find_elements(
                    "css selector", ".widget-slider"), 240, f"the {s} view's sliders")  # fmt: skip
                time.sleep(1.0)  # the views' first messages (a slider's snapped value) go out as they render
                timings[s] = time.perf_counter() - t
                cell = driver.find_elements("css selector", ".jp-Notebook .jp-Cell")[i]
                driver.execute_script("arguments[0].scrollIntoView(true);", cell)
                time.sleep(0.3)
                layout[s] = driver.execute_script(_LAYOUT_JS, cell)
                cell.find_element("css selector", ".jp-OutputArea-output").screenshot(
                    str(out_dir / f"browser_view_{s}.png")
                )
            check = len(scenes) + 1
            run_cell(driver, check)
            text = _wait(lambda: "RESULT " in output_text(driver, check) and output_text(driver, check), 600,
                         "the read-back cell")  # fmt: skip
            result = json.loads(text.split("RESULT ", 1)[1].strip().splitlines()[0])
            tune = None
            if "fourbar" in scenes:
                fb = driver.find_elements("css selector", ".jp-Notebook .jp-Cell")[1 + scenes.index("fourbar")]
                driver.execute_script("arguments[0].scrollIntoView(true);", fb)
                button = next(b for b in fb.find_elements("css selector", "button") if "tune PID" in b.text)
                t = time.perf_counter()
                button.click()
                # the kernel handles the click's message before the next cell's request (one shell channel, in
                # order): the read-back cell waits for the tuning, then the browser has the gains it was sent
                last = check + 1
                run_cell(driver, last)
                text = _wait(lambda: "TUNE " in output_text(driver, last) and output_text(driver, last), 600,
                             "the tune read-back")  # fmt: skip
                timings["tune"] = time.perf_counter() - t
                time.sleep(2.0)  # the browser's answer to the new gains
                fb = driver.find_elements("css selector", ".jp-Notebook .jp-Cell")[1 + scenes.index("fourbar")]
                driver.execute_script("arguments[0].scrollIntoView(true);", fb)
                time.sleep(0.5)
                layout["fourbar_tuned"] = driver.execute_script(_LAYOUT_JS, fb)
                layout["fourbar_tuned"]["message_in_browser"] = "tune_pid: χ" in fb.text
                fb.find_element("css selector", ".jp-OutputArea-output").screenshot(
                    str(out_dir / "browser_view_fourbar_tuned.png")
                )
                tune = json.loads(text.split("TUNE ", 1)[1].strip().splitlines()[0])
        finally:
            if driver is not None:
                driver.quit()
            lab.terminate()
            try:
                lab.wait(20)
            except subprocess.TimeoutExpired:
                lab.kill()
    ok_all = True
    for s in scenes:
        r, lay = result[s], layout[s]
        ok = not r["sliders_changed"] and not r["values_changed"] and not r["error"]
        fits = not lay["overflowing"] and not lay["page_scroll"]
        scale = (lay["img_shown"] / lay["img_natural"]) if lay.get("img_natural") else None
        rows.append(
            dict(
                name=s,
                method=f"explore('{s}') shown in JupyterLab, headless Chromium {WINDOW[0]} px wide",
                error=None,
                median_s=timings[s],
                compile_s=None,
                repeats=1,
                unchanged=ok,
                fits_1000px=fits,
                sliders_changed=r["sliders_changed"],
                values_changed=r["values_changed"],
                readouts=dict(zip(lay["labels"], lay["readouts"])),
                legend_px=None if scale is None else 9 * scale,
                error_text=r["error"],
            )  # fmt: skip
        )
        ok_all &= ok and fits
        print(f"{s:10s} unchanged={ok} fits={fits} readouts={dict(zip(lay['labels'], lay['readouts']))}"
              f" legend≈{'?' if scale is None else f'{9 * scale:.1f}'} px changed={r['sliders_changed']} "
              f"{r['values_changed']} {r['error']}")  # fmt: skip
    headline = [dict(what="views opened in the browser with every slider and number unchanged",
                     value=sum(r["unchanged"] for r in rows), unit=f"of {len(rows)}", target=f"{len(rows)}")]  # fmt: skip
    extra = {"layout": layout, "timings_s": timings, "total_s": time.perf_counter() - t_all}
    if tune is not None:
        gains_ok = all(tune["sliders"][k] == v for k, v in tune["headless"].items())
        shown = "tune_pid: χ" in tune["status"] and layout["fourbar_tuned"]["message_in_browser"]
        rd = dict(zip(layout["fourbar_tuned"]["labels"], layout["fourbar_tuned"]["readouts"]))
        shown_gains = {
            g: float(next(v for k, v in rd.items() if k.startswith(g[0].upper() + g[1:]))) for g in tune["headless"]
        }
        readouts_ok = all(abs(shown_gains[g] - v) <= 5e-4 * abs(v) for g, v in tune["headless"].items())  # 4 digits
        shown &= readouts_ok
        print(f"tune: kernel gains = headless tune_pid: {gains_ok} {tune['sliders']} vs {tune['headless']}; "
              f"message shown: {shown}; browser readouts {rd}")  # fmt: skip
        headline.append(dict(what="tune button in the browser: gains equal to tune_pid headless, message shown",
                             value=float(gains_ok and shown), unit="yes=1", target="1"))  # fmt: skip
        extra["tune"] = dict(tune, readouts=rd, gains_equal=gains_ok, message_and_readouts_shown=shown)
        ok_all &= gains_ok and shown
    path = write_results("browser_view", rows, headline, args.quick, extra)
    print(f"browser_view: {'all good' if ok_all else 'FAILED'} in {time.perf_counter() - t_all:.0f} s; wrote {path}")
    return 0 if ok_all else 1


if __name__ == "__main__":
    sys.exit(main())
