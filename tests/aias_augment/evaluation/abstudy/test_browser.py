"""End to end in a real headless browser: Debian's chromium driven by Playwright (which cannot download its own
browser here), against a real server process. Screenshots go to the test's tmp folder, and also to
``$ABSTUDY_SCREENSHOTS`` when that is set."""

import os
import shutil
from pathlib import Path

import pytest

from aias_augment.evaluation.abstudy.build import build_study, load_study
from aias_augment.evaluation.abstudy.store import VoteStore
from tests.aias_augment.evaluation.abstudy.helpers import Server, image_arms, make_clip

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
KEYS = {"ArrowLeft": "left", "ArrowRight": "right", "ArrowDown": "tie"}

pytestmark = pytest.mark.skipif(
    not Path(CHROMIUM).exists(), reason=f"{CHROMIUM} missing: `make setup` installs Debian's chromium"
)


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


def _save(page, tmp_path, name):
    path = tmp_path / name
    page.screenshot(path=str(path), full_page=True)
    if os.environ.get("ABSTUDY_SCREENSHOTS"):
        dst = Path(os.environ["ABSTUDY_SCREENSHOTS"])
        dst.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, dst / name)
    print(f"screenshot: {path}")
    return path


def _open(browser, srv):
    page = browser.new_page(viewport={"width": 1280, "height": 760})
    seen, errors = [], []
    page.on("request", lambda r: seen.append(r.url))
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.set_default_timeout(15000)
    page.goto(srv.url + "/")
    return page, seen, errors


def test_rate_a_study_with_the_keyboard(browser, tmp_path):
    build_study(image_arms(tmp_path, 3), tmp_path / "study", seed=4)
    study = load_study(tmp_path / "study")
    n = len(study.pairs)
    with Server(tmp_path / "study") as srv:
        page, seen, errors = _open(browser, srv)
        page.wait_for_selector("body[data-state=name]")
        assert "two versions of the same scene" in page.inner_text("#intro")
        assert page.inner_text("#total-pairs") == str(n)
        page.fill("#name", "E2E rater")
        page.keyboard.press("Enter")
        chosen = {}
        keys = list(KEYS)
        for i in range(n):
            page.wait_for_selector("body[data-state=ready]")
            pid = page.get_attribute("#trial", "data-pair-id")
            assert pid in study.pairs and pid not in chosen
            assert page.inner_text("#progress-text").startswith(f"Pair {i + 1} of {n}")
            widths = page.eval_on_selector_all(".media img", "els => els.map(e => e.naturalWidth)")
            assert widths == [64, 64]  # both sides shown, loaded
            if i == 1:
                _save(page, tmp_path, "abstudy_trial.png")
            key = keys[i % 3]
            page.keyboard.press(key)
            chosen[pid] = KEYS[key]
        page.wait_for_selector("body[data-state=done]")
        assert page.inner_text("#done-count") == str(n)
        page.keyboard.press("Enter")  # the focused "See the results" link
        page.wait_for_url(srv.url + "/results")
        page.wait_for_selector("body[data-state=ready]")
        assert page.locator("#comparisons tbody tr").count() == 2
        assert page.locator("#raters tbody tr").count() == 1
        assert "E2E rater" in page.inner_text("#raters")
        _save(page, tmp_path, "abstudy_results.png")
        # what the browser sent is what was stored, one vote per pair
        votes = VoteStore(tmp_path / "study" / "votes.sqlite").votes()
        assert {v["pair_id"]: v["choice"] for v in votes if v["rater"] == "E2E rater"} == chosen
        assert len(votes) == n and all(v["ms"] is not None and v["ms"] >= 0 for v in votes)
        # coming back with the cookie: nothing left to rate
        page.goto(srv.url + "/")
        page.wait_for_selector("body[data-state=done]")
        assert page.inner_text("#who-name") == "E2E rater"
        # every request went to the study server (nothing from a CDN), and the page raised no error
        assert seen and all(u.startswith(srv.url + "/") for u in seen), [u for u in seen if srv.url not in u]
        assert not errors
        page.close()


def test_clip_pairs_play_and_space_replays(browser, tmp_path):
    for arm, seed in (("full", 1), ("naive_paste", 2)):
        for j in range(2):
            make_clip(tmp_path / arm / f"clip{j}", f"/clips/c{j}.mp4", seed=seed * 10 + j, n_frames=5, fps=20)
    build_study([tmp_path / "naive_paste", tmp_path / "full"], tmp_path / "study")
    with Server(tmp_path / "study") as srv:
        page, seen, errors = _open(browser, srv)
        page.wait_for_selector("body[data-state=name]")
        assert page.is_visible("text=replay the videos")
        page.fill("#name", "clip rater")
        page.click("#start")
        page.wait_for_selector("body[data-state=ready]")
        assert page.locator(".media canvas").count() == 2
        # (attribute selectors, not wait_for_function: the page's CSP forbids the eval that one needs)
        page.wait_for_selector("body[data-plays='1']")
        page.keyboard.press("Space")
        page.wait_for_selector("body[data-plays='2']")
        assert page.evaluate("window.scrollY") == 0  # space replays, it does not scroll
        first = page.get_attribute("#trial", "data-pair-id")
        page.keyboard.press("c")  # the other "cannot tell" key
        page.wait_for_selector(f"body[data-state=ready] #trial:not([data-pair-id='{first}'])")
        page.click("#btn-right")  # buttons work as well as keys
        page.wait_for_selector("body[data-state=done]")
        votes = {v["pair_id"]: v["choice"] for v in VoteStore(tmp_path / "study" / "votes.sqlite").votes()}
        assert votes[first] == "tie" and sorted(votes.values()) == ["right", "tie"]
        assert all(u.startswith(srv.url + "/") for u in seen) and not errors
        page.close()
