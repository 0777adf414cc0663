"""scripts/plot_training.py: a PNG from a synthetic progress.csv, and a clear error for missing columns."""

import ast
import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "plot_training.py"


def csv_fields() -> list[str]:
    """CSV_FIELDS of ppo.py's CSV log (baselines/ppo/checkpoints.py), read from its source (importing it
    loads torch and the networks)."""
    tree = ast.parse((ROOT / "baselines" / "ppo" / "checkpoints.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "CSV_FIELDS" for t in node.targets):
            return ast.literal_eval(node.value)
    raise AssertionError("CSV_FIELDS not found in baselines/ppo/checkpoints.py")


def write_csv(path: Path, fields: list[str], rows: list[dict]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows([{k: r.get(k, "") for k in fields} for r in rows])
    return path


def synthetic_rows(n: int = 60) -> list[dict]:
    rng = np.random.default_rng(0)
    rows = []
    for i in range(n):
        stage = "cp1" if i < n // 2 else "cp2"
        level = i / n if stage == "cp1" else (i - n // 2) / n
        row = dict(global_step=(i + 1) * 800, iteration=i + 1, stage=stage, sps=400.0)
        if i % 7 != 3:  # some iterations finish no episode: empty cells
            place = float(np.clip(level + rng.normal(0, 0.1), 0, 1))
            row.update(place_success=place, pick_success=min(1.0, place + 0.2), extrinsic_return=10 * place)
        if i % 10 == 9:
            row.update(eval_place_success=level, eval_pick_success=level)
        rows.append(row)
    rows[-1]["eval_place_success"] = math.nan  # ppo.py writes 'nan' when no eval episode ended
    return rows


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=120)


def test_plot_training_writes_a_png(tmp_path):
    from matplotlib.image import imread

    fields = csv_fields()
    path = write_csv(tmp_path / "demo_run" / "progress.csv", fields, synthetic_rows())
    out = tmp_path / "images" / "training.png"
    res = run("--csv", str(path), "--out", str(out), "--window", "5")
    assert res.returncode == 0, res.stderr
    assert out.is_file()
    img = imread(out)
    h, w = img.shape[:2]
    assert 400 < h < w < 2000, img.shape  # 10 x 7 inches at 120 dpi: wider than tall
    rgb = img[..., :3]
    assert rgb.std() > 0.05
    assert (rgb.min(axis=-1) < 0.95).mean() > 0.02  # more than 2% of pixels are not white


def test_plot_training_overlays_runs(tmp_path):
    fields = csv_fields()
    a = write_csv(tmp_path / "a" / "progress.csv", fields, synthetic_rows())
    b = write_csv(tmp_path / "b" / "progress.csv", fields, synthetic_rows(40))
    out = tmp_path / "overlay.png"
    res = run("--csv", str(a), str(b), "--out", str(out), "--title", "a vs b")
    assert res.returncode == 0, res.stderr
    assert out.is_file()


def test_plot_training_names_missing_columns(tmp_path):
    fields = [f for f in csv_fields() if f not in ("place_success", "extrinsic_return")]
    path = write_csv(tmp_path / "bad" / "progress.csv", fields, synthetic_rows(5))
    res = run("--csv", str(path), "--out", str(tmp_path / "bad.png"))
    assert res.returncode != 0
    assert str(path) in res.stderr and "place_success" in res.stderr and "extrinsic_return" in res.stderr
    assert not (tmp_path / "bad.png").exists()

    res = run("--csv", str(tmp_path / "nowhere.csv"), "--out", str(tmp_path / "x.png"))
    assert res.returncode != 0 and "nowhere.csv" in res.stderr


def test_paper_figures_3_and_4_are_drawn_from_small_csvs(tmp_path):
    from matplotlib.image import imread

    fields = csv_fields()
    rows = synthetic_rows(80)
    for i, row in enumerate(rows):
        row["stage"] = ("cp1", "cp2", "cp3", "cp4")[i // 20]
        row["intrinsic_return"] = 0.5 * math.exp(-i / 30)
    general = write_csv(tmp_path / "paper_general_agent" / "progress.csv", fields, rows)
    controls = [write_csv(tmp_path / name / "progress.csv", fields, synthetic_rows(20))
                for name in ("control_ceiling", "control_window", "control_flooring")]
    fig3, fig4 = tmp_path / "fig3.png", tmp_path / "fig4.png"
    res = run("--figure", "fig3", "--csv", str(general), "--out", str(fig3))
    assert res.returncode == 0, res.stderr
    img = imread(fig3)
    assert img.shape[1] > 1.5 * img.shape[0], "extrinsic and intrinsic side by side"
    res = run("--figure", "fig4", "--csv", str(general), *map(str, controls), "--out", str(fig4))
    assert res.returncode == 0, res.stderr
    assert (imread(fig4)[..., :3].min(axis=-1) < 0.95).mean() > 0.02
    res = run("--figure", "fig4", "--csv", str(general), "--out", str(tmp_path / "x.png"))
    assert res.returncode != 0 and "control groups" in res.stderr


def test_max_steps_draws_only_the_rows_up_to_it_and_says_when_none_are(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("plot_training", SCRIPT)
    plot_training = importlib.util.module_from_spec(spec)
    sys.modules["plot_training"] = plot_training  # dataclasses look their module up
    spec.loader.exec_module(plot_training)
    path = write_csv(tmp_path / "a" / "progress.csv", csv_fields(), synthetic_rows(60))  # 800 env steps a row
    assert len(plot_training.load(path, max_steps=24_000)["global_step"]) == 30
    assert plot_training.load(path, max_steps=24_000)["stage"] == ["cp1"] * 30
    out = tmp_path / "cp1.png"
    res = run("--csv", str(path), str(path), "--max-steps", "24000", "--out", str(out))
    assert res.returncode == 0 and out.stat().st_size > 0, res.stderr
    res = run("--csv", str(path), "--max-steps", "100", "--out", str(tmp_path / "x.png"))
    assert res.returncode != 0 and "no rows up to env step 100" in res.stderr
