"""`frfit.fit` inside Python against the `frfit fit` command line, side by side.

    python bench/fit_vs_cli.py DATA.csv [--band 20:2000] [--hold zoh:10000] [--pairs 10]

Alternates the two (so that a slow phase of the machine hits both) and prints the
median and range of: the CLI's whole process (`frfit fit DATA --out ... --quiet`:
start, CSV read, fit, model file), and in Python `frfit.fit(data, ...)` alone (the data
read once before; interpreter start and imports excluded) and `frfit.read` + `fit`.
The CLI binary is target/release/frfit of the workspace, or --cli PATH.
"""

import argparse
import pathlib
import statistics
import subprocess
import tempfile
import time

import frfit


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("data")
    ap.add_argument("--band")
    ap.add_argument("--hold")
    ap.add_argument("--pairs", type=int, default=10)
    root = pathlib.Path(__file__).resolve().parents[3]
    ap.add_argument("--cli", default=str(root / "target" / "release" / "frfit"))
    a = ap.parse_args()
    out = pathlib.Path(tempfile.mkdtemp()) / "model.json"
    cli = [a.cli, "--quiet", "fit", a.data, "--out", str(out)]
    kw = {}
    if a.band:
        cli += ["--band", a.band]
        kw["band"] = a.band
    if a.hold:
        cli += ["--hold", a.hold]
        kw["hold"] = a.hold
    data = frfit.read(a.data)
    t_cli, t_fit, t_read_fit = [], [], []
    for _ in range(a.pairs):
        t = time.perf_counter()
        subprocess.run(cli, check=True)
        t_cli.append(time.perf_counter() - t)
        t = time.perf_counter()
        model = frfit.fit(data, **kw)
        t_fit.append(time.perf_counter() - t)
        t = time.perf_counter()
        frfit.fit(frfit.read(a.data), **kw)
        t_read_fit.append(time.perf_counter() - t)
    cli_model = frfit.load_model(out)
    same = max(abs(m.f_hz - c.f_hz) / c.f_hz for m, c in zip(model.modes, cli_model.modes))
    print(f"{a.pairs} pairs on {a.data} {kw}")
    for name, v in [("CLI whole process", t_cli), ("python fit", t_fit), ("python read + fit", t_read_fit)]:
        print(f"  {name:20s} median {statistics.median(v):.3f} s  (min {min(v):.3f}, max {max(v):.3f})")
    print(f"  python fit / CLI: {statistics.median(t_fit) / statistics.median(t_cli):.3f}; "
          f"read + fit / CLI: {statistics.median(t_read_fit) / statistics.median(t_cli):.3f}")
    print(f"  same model: {len(model.modes)} modes, largest relative frequency difference {same:.1e}")


if __name__ == "__main__":
    main()
