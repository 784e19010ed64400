import json

import cv2

from aias_augment.cli.scenes import main


def test_index_name_query(tmp_path, frames, capsys):
    clip = tmp_path / "clip"
    clip.mkdir()
    for i, (ref, img) in enumerate(frames[:4] + frames[4:6]):
        cv2.imwrite(str(clip / f"{i:02d}.png"), img)
    idx = tmp_path / "scenes.npz"
    assert (
        main(
            [
                "index",
                str(clip),
                "--out",
                str(idx),
                "--words",
                "128",
                "--features",
                "300",
                "--max-side",
                "400",
                "--quiet",
            ]
        )
        == 0
    )
    capsys.readouterr()
    h, w = frames[1][1].shape[:2]
    cv2.imwrite(str(tmp_path / "q.jpg"), cv2.resize(frames[1][1][h // 6 :, w // 5 :], None, fx=0.9, fy=0.9))
    assert main(["query", "--index", str(idx), "--image", str(tmp_path / "q.jpg"), "--json", "--top", "2"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["hits"][0]["frame"] == "01.png" and out["hits"][0]["inliers"] > 0
    assert (
        main(
            [
                "name",
                "--index",
                str(idx),
                "--name",
                "road",
                "--image",
                str(clip / "00.png"),
                "--region",
                str(w // 3),
                str(int(0.72 * h)),
                str(w // 3),
                str(h // 4),
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["query", "--index", str(idx), "--words", "road", "--json", "--top", "6"]) == 0
    hits = json.loads(capsys.readouterr().out)["hits"]
    assert len(hits) == 6 and hits[0]["score"] >= hits[-1]["score"]
