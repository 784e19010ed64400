import csv
import json

from aias_augment.evaluation.abstudy.build import load_study
from aias_augment.evaluation.abstudy.cli import main
from aias_augment.evaluation.abstudy.store import VoteStore
from tests.aias_augment.evaluation.abstudy.helpers import image_arms


def test_build_then_report(tmp_path, capsys):
    arms = image_arms(tmp_path, 3)
    out = tmp_path / "study"
    assert (
        main(
            [
                "build",
                "--arms",
                *map(str, arms),
                "--names",
                "naive",
                "full",
                "noshadow",
                "--baseline",
                "naive",
                "--design",
                "all-pairs",
                "--seed",
                "1",
                "--title",
                "Cones",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert summary["pairs"] == 15 and summary["baseline"] == "naive"
    study = load_study(out)
    assert study.meta["title"] == "Cones"
    store = VoteStore(out / "votes.sqlite")
    for pid, k in study.key.items():  # one rater who always prefers "full"
        if "full" in (k["left"], k["right"]):
            store.add_vote("ann", pid, "left" if k["left"] == "full" else "right", k["left"], k["right"])
    assert main(["report", str(out), "--csv", str(tmp_path / "r.csv"), "--votes-csv", str(tmp_path / "v.csv")]) == 0
    text = capsys.readouterr().out
    assert "Cones: 15 pairs (images), 1 raters, 10 votes; baseline naive" in text
    lines = [ln for ln in text.splitlines() if ln.startswith(("full ", "noshadow "))]
    assert [ln.split()[:2] for ln in lines] == [["full", "naive"], ["noshadow", "naive"], ["full", "noshadow"]]
    assert "100.0 %" in lines[0] and "56.6 - 100.0 %" in lines[0]  # Wilson for 5 of 5
    rows = list(csv.DictReader(open(tmp_path / "r.csv")))
    assert [(r["method"], r["opponent"], r["wins"]) for r in rows] == [
        ("full", "naive", "5"),
        ("noshadow", "naive", "0"),
        ("full", "noshadow", "5"),
    ]
    assert len(list(csv.DictReader(open(tmp_path / "v.csv")))) == 10
    assert main(["report", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["votes"] == 10


def test_errors_exit_2_with_a_message(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "no study.json" in capsys.readouterr().err
    assert main(["serve", str(tmp_path)]) == 2
    arms = image_arms(tmp_path, 2)
    assert main(["build", "--arms", str(arms[0]), "--out", str(tmp_path / "s")]) == 2
    assert "at least two arms" in capsys.readouterr().err
