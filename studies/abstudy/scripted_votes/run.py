"""Vote on a study through its page in headless chromium, with the keyboard, as *scripted* raters.

This exercises a study end to end (server, page, keys, stored votes, results page, report) and takes the README
screenshots. Scripted raters are not people: each presses left, right or "cannot tell" at random (seeded), so the
scores it produces say nothing about realism. Their ids start with ``script-`` so they are easy to tell apart.

    python -m studies.abstudy.scripted_votes out/abstudy_study --raters 3 --screenshots studies/abstudy/scripted_votes/result
"""

from __future__ import annotations

import argparse
import random
import subprocess
import sys
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("study")
    ap.add_argument("--raters", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tie-share", type=float, default=0.15, help="share of 'cannot tell' presses")
    ap.add_argument("--screenshots", help="folder for trial.jpg and results.jpg")
    a = ap.parse_args(argv)
    from playwright.sync_api import sync_playwright

    from aias_augment.evaluation.abstudy import compute_report, format_report, load_study
    from aias_augment.evaluation.abstudy.store import VoteStore

    shot_at = min(2, len(load_study(a.study).pairs) - 1)  # the trial screenshot: the third pair (or the last)
    proc = subprocess.Popen(
        [sys.executable, "-m", "aias_augment.evaluation.abstudy.cli", "serve", a.study, "--port", "0"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        url = line.split(" on ")[1].split()[0].rstrip("/")
        rng = random.Random(a.seed)
        shots = Path(a.screenshots) if a.screenshots else None
        if shots:
            shots.mkdir(parents=True, exist_ok=True)
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            for r in range(a.raters):
                ctx = browser.new_context(viewport={"width": 1400, "height": 720})  # its own cookie jar
                page = ctx.new_page()
                page.set_default_timeout(30000)
                page.goto(url + "/")
                page.wait_for_selector("body[data-state=name]")
                page.fill("#name", f"script-{r + 1}")
                page.keyboard.press("Enter")
                n = 0
                while True:
                    page.wait_for_selector("body[data-state=ready], body[data-state=done]")
                    if page.get_attribute("body", "data-state") == "done":
                        break
                    if shots and r == 0 and n == shot_at:
                        page.screenshot(path=str(shots / "trial.jpg"), type="jpeg", quality=85)
                    u = rng.random()
                    page.keyboard.press(
                        "ArrowDown" if u < a.tie_share else "ArrowLeft" if u < (1 + a.tie_share) / 2 else "ArrowRight"
                    )
                    n += 1
                print(f"script-{r + 1}: {n} votes")
                if r == a.raters - 1:
                    page.keyboard.press("Enter")  # the focused results link
                    page.wait_for_url(url + "/results")
                    page.wait_for_selector("body[data-state=ready]")
                    if shots:
                        page.screenshot(path=str(shots / "results.jpg"), type="jpeg", quality=85, full_page=True)
                ctx.close()
            browser.close()
    finally:
        proc.terminate()
        proc.wait(15)
    study = load_study(a.study)
    print(format_report(compute_report(study, VoteStore(Path(a.study) / "votes.sqlite").votes())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
