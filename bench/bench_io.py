"""Input loading: robocal's validated loaders vs the plain library calls they wrap.

Measured in one run, on the same generated files:

* CSV -- :func:`robocal.io.load_csv` (header units, row/line bookkeeping,
  finiteness check) against ``numpy.loadtxt`` alone (the floor: no checks) and
  against robocal's careful ``csv``-module path, which files with quoted cells
  take (and which every file took before 2026-11-27);
* YAML -- :func:`robocal.io.load_document` against ``yaml.safe_load`` (the
  pure-Python parser) and ``yaml.load(..., CSafeLoader)`` (libyaml).

Ratios > 1 mean the first is faster. Run: ``python bench/bench_io.py`` (``--rows N``).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import yaml

from robocal.io import load_csv, load_document
from _timing import best_of  # bench/ is on sys.path when a script runs
from robocal.io._load import _csv_table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=200_000, help="CSV rows (8 columns)")
    ap.add_argument("--points", type=int, default=10_000, help="YAML points (two (N, 2) arrays)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as tmp:
        csv_path = Path(tmp) / "t.csv"
        data = rng.normal(size=(args.rows, 8))
        csv_path.write_text("t [s],a [m],b,c,d,e,f,g\n" + "".join(",".join(f"{v:.9g}" for v in r) + "\n" for r in data))
        text = csv_path.read_text()
        kept = [(n, ln) for n, ln in enumerate(text.splitlines(), 1)]
        t_ours = best_of(lambda: load_csv(csv_path))
        t_np = best_of(lambda: np.loadtxt(csv_path, delimiter=",", skiprows=1))
        t_careful = best_of(lambda: _csv_table(kept, "t.csv"))
        print(f"CSV {args.rows} x 8: load_csv {t_ours:.3f} s; numpy.loadtxt alone {t_np:.3f} s "
              f"(ratio {t_np / t_ours:.2f}); csv-module path {t_careful:.3f} s (ratio {t_careful / t_ours:.2f})")

        yaml_path = Path(tmp) / "p.yaml"
        pts = rng.normal(size=(args.points, 2)).round(4).tolist()
        yaml_path.write_text(yaml.safe_dump({"points": {"world": pts, "joint_angles": pts}}, default_flow_style=None))
        ytext = yaml_path.read_text()
        t_doc = best_of(lambda: load_document(yaml_path))
        t_py = best_of(lambda: yaml.safe_load(ytext))
        t_c = best_of(lambda: yaml.load(ytext, Loader=yaml.CSafeLoader)) if hasattr(yaml, "CSafeLoader") else float("nan")
        print(f"YAML {args.points} points x 2 arrays: load_document {t_doc:.3f} s; yaml.safe_load {t_py:.3f} s "
              f"(ratio {t_py / t_doc:.2f}); CSafeLoader alone {t_c:.3f} s (ratio {t_c / t_doc:.2f})")


if __name__ == "__main__":
    main()
