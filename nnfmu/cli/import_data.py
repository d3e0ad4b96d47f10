"""``nnfmu import csv|mat|npz|robot-benchmark|nonlinear-benchmark FILE... -o DIR``: external data to a dataset folder.

The dataset is built whole in memory and written atomically at the end, so a
failed import writes nothing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

FORMATS = ("csv", "mat", "npz", "robot-benchmark", "nonlinear-benchmark")

_DESCRIPTION = (
    "Convert measured data into a dataset folder (meta.json, train.npz, test.npz, valid.npz). csv, mat, npz: each "
    "FILE is one training trajectory; pick the columns with --inputs and --outputs (names or 0-based indices; "
    "NAME=COLUMN names the channel). The test split (required) comes from other files (--test) or from other "
    "columns of the same files (--test-columns); the validation split likewise, or as a share of the training "
    "trajectories. robot-benchmark: FILE is the industrial robot benchmark's .mat. nonlinear-benchmark: FILE is "
    "the name of a benchmark of the nonlinear-benchmarks package (downloaded once into its cache), e.g. "
    "Cascaded_Tanks, Silverbox, WienerHammerBenchMark, EMPS, CED, ParWH, F16. Nothing is written unless the whole "
    "import succeeds."
)

_EPILOG = (
    "Examples. One CSV with the columns uEst, uVal, yEst, yVal sampled every 4 s: nnfmu import csv tanks.csv "
    "--inputs u=uEst --outputs y=yEst --test-columns u=uVal,y=yVal --units u=V,y=V --Ts 4 -o data/tanks. "
    "The F-16 benchmark's CSVs as distributed (trailing commas, the rate Fs in the first row only): nnfmu import "
    "csv F16Data_FullMSine_Level5.csv --inputs Force --outputs Acceleration1 Acceleration2 Acceleration3 "
    "--fs-column Fs --test F16Data_FullMSine_Level6_Validation.csv -o data/f16. Positions in messages are 0-based. "
    "The dataset (and the models trained on it) is named after the -o folder."
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import", help="convert measured data (CSV, MAT, NPZ, the robot or nonlinear benchmarks) into "
                                      "a dataset folder", description=_DESCRIPTION, epilog=_EPILOG)
    p.add_argument("format", choices=FORMATS, help="the kind of data")
    p.add_argument("files", nargs="+", metavar="FILE",
                   help="the training files (one trajectory each); robot-benchmark: the .mat; "
                        "nonlinear-benchmark: the benchmark's name")
    p.add_argument("-o", "--out", required=True, help="dataset folder to write")
    p.add_argument("--force", action="store_true", help="replace an existing dataset folder")
    cols = p.add_argument_group("columns (csv, mat, npz)")
    cols.add_argument("--inputs", metavar="COLS", nargs="+", help="input columns, separated by commas or spaces: "
                      "names, 0-based indices, or NAME=COLUMN to name the channel (a .mat/.npz matrix gives all its "
                      "columns); nonlinear-benchmark: the channel names (default u1, u2, ...)")
    cols.add_argument("--outputs", metavar="COLS", nargs="+", help="output columns, in the same form as --inputs; "
                      "nonlinear-benchmark: the channel names (default y1, y2, ...)")
    cols.add_argument("--units", metavar="UNITS", help="units, comma-separated: one per channel (inputs first) or "
                      "NAME=UNIT, e.g. u=V,y=m")
    timing = cols.add_mutually_exclusive_group()
    timing.add_argument("--Ts", type=float, metavar="SECONDS", help="the sample time in seconds; forces one Ts on "
                        "files (or nonlinear-benchmark records) whose sample times disagree")
    timing.add_argument("--time", metavar="COL", help="the column holding time in seconds (Ts is its median step, "
                        "rounded to the decimals the time stamps carry)")
    timing.add_argument("--Ts-column", metavar="COL", help="a column holding the sample time in seconds, filled in "
                        "one or more rows (the others empty), or a single number of a .mat/.npz file")
    timing.add_argument("--fs-column", metavar="COL", help="the same for the sample rate in Hz, e.g. the F-16 "
                        "benchmark's Fs, given in the first data row only")
    cols.add_argument("--resample", type=int, default=1, metavar="Q",
                      help="keep every Q-th sample after an anti-aliasing low-pass filter (zero-phase FIR, cut off "
                           "at the new Nyquist frequency); Ts becomes Q times the files' (default 1)")
    splits = p.add_argument_group("test and validation splits")
    splits.add_argument("--test", nargs="+", metavar="FILE", help="files of the test split (one trajectory each)")
    splits.add_argument("--test-columns", metavar="COLS",
                        help="the test split's columns in the training files (or in --test files): one per input "
                             "and output, in their order, or NAME=COLUMN by channel name")
    splits.add_argument("--valid", nargs="+", metavar="FILE", help="files of the validation split")
    splits.add_argument("--valid-columns", metavar="COLS", help="the validation split's columns, as --test-columns")
    share = splits.add_mutually_exclusive_group()
    share.add_argument("--valid-fraction", type=float, metavar="F",
                       help="move this share of the training trajectories (chosen with --seed) to validation; "
                            "a single training record gives its last F instead")
    share.add_argument("--valid-trajectories", type=int, metavar="N",
                       help="move N training trajectories (chosen with --seed) to validation")
    splits.add_argument("--seed", type=int, default=0, help="seeds the choice of validation trajectories (default 0)")
    p.add_argument("--data-dir", metavar="DIR", help="nonlinear-benchmark: where the package keeps its downloads "
                                                     "(default: its own cache folder)")
    p.set_defaults(func=_run)


def parse_items(text: str | None, what: str):
    """``"a,b"`` -> ``["a", "b"]``; ``"x=a,y=b"`` -> ``{"x": "a", "y": "b"}``; None stays None."""
    from nnfmu.errors import ConfigError

    if text is None:
        return None
    items = [t.strip() for t in text.split(",") if t.strip()]
    named = [t for t in items if "=" in t]
    if not named:
        return items
    if len(named) != len(items):
        raise ConfigError(f"{what}: write every item as NAME=VALUE or none of them, got {text!r}")
    pairs = [t.split("=", 1) for t in items]
    return {k.strip(): v.strip() for k, v in pairs}


def _entries(text: str | None, flag: str):
    """``--inputs``: a list where each item is a column or a (name, column) pair."""
    from nnfmu.errors import ConfigError

    if text is None:
        raise ConfigError(f"{flag} is required for csv, mat and npz: name the columns (or 0-based indices)")
    return [tuple(t.split("=", 1)) if "=" in t else t for t in (s.strip() for s in text.split(",")) if t]


def _tabular(args: argparse.Namespace):
    from nnfmu.data import load_files

    files = {"train": args.files}
    columns = {}
    for split in ("test", "valid"):
        if getattr(args, split):
            files[split] = getattr(args, split)
        given = parse_items(getattr(args, f"{split}_columns"), f"--{split}-columns")
        if given is not None:
            columns[split] = given
    return load_files(files, inputs=_entries(args.inputs, "--inputs"), outputs=_entries(args.outputs, "--outputs"),
                      columns=columns, units=parse_items(args.units, "--units"), Ts=args.Ts,
                      time_column=args.time, Ts_column=args.Ts_column, fs_column=args.fs_column,
                      resample=args.resample, valid_fraction=args.valid_fraction,
                      valid_trajectories=args.valid_trajectories, seed=args.seed, fmt=args.format)


def _single(args: argparse.Namespace):
    from nnfmu.data import load_robot_benchmark
    from nnfmu.data.benchmarks import fetch_benchmark
    from nnfmu.errors import ConfigError

    named = ("inputs", "outputs", "Ts") if args.format == "nonlinear-benchmark" else ()
    tabular_only = [f"--{k.replace('_', '-')}" for k in ("inputs", "outputs", "time", "Ts_column", "fs_column", "test",
                                                          "valid", "test_columns", "valid_columns", "Ts")
                    if getattr(args, k) is not None and k not in named] + (["--resample"] if args.resample != 1 else [])
    if len(args.files) != 1 or tabular_only:
        raise ConfigError(f"{args.format} takes one FILE and none of {', '.join(tabular_only) or 'the column options'}"
                          f"; got {len(args.files)} file(s)")
    if args.format == "robot-benchmark":
        ds = load_robot_benchmark(args.files[0])
    else:
        names = {k: _channel_names(getattr(args, k), f"--{k}") for k in ("inputs", "outputs")}
        ds = fetch_benchmark(args.files[0], data_dir=args.data_dir, Ts=args.Ts, **names)
    ds = ds.with_units(parse_items(args.units, "--units"))
    if args.valid_fraction is not None or args.valid_trajectories is not None:
        ds = ds.with_validation(args.valid_fraction, seed=args.seed, n_traj=args.valid_trajectories)
    return ds


def _channel_names(text: str | None, flag: str) -> list[str]:
    """nonlinear-benchmark: ``--inputs u`` names the channels (default u1, u2, ... and y1, y2, ...)."""
    from nnfmu.errors import ConfigError
    from nnfmu.identifiers import is_c_identifier

    names = [t.strip() for t in (text or "").split(",") if t.strip()]
    bad = [n for n in names if not is_c_identifier(n)]
    if bad:
        raise ConfigError(f"{flag}: for nonlinear-benchmark it names the channels, one identifier per channel "
                          f"(e.g. {flag} u), got {bad}")
    return names


def _named_after(ds, out: str):
    """The dataset named after its folder: models trained on it are called ``<folder>_<arch>``."""
    from nnfmu.identifiers import to_c_identifier

    name = to_c_identifier(Path(out).resolve().name, prefix="d_")
    return ds.replace(source={**ds.source, "name": "data" if name == "d_" else name})


def _run(args: argparse.Namespace) -> int:
    from nnfmu.data import save_dataset
    from nnfmu.data.storage import check_replaceable
    from nnfmu.errors import DataFileError

    if Path(args.out).exists() and not args.force:  # before reading what may be large files
        raise DataFileError(f"{args.out} already exists; choose another folder or pass --force")
    check_replaceable(args.out)  # --force replaces a dataset folder, never a folder of other files
    for key in ("inputs", "outputs"):  # "--outputs a b c" and "--outputs a,b,c" are the same
        if getattr(args, key) is not None:
            setattr(args, key, ",".join(getattr(args, key)))
    ds = _named_after(_tabular(args) if args.format in ("csv", "mat", "npz") else _single(args), args.out)
    save_dataset(ds, args.out, overwrite=args.force)
    print(f"wrote {args.out}")
    print(ds.summary())
    if ds.valid is None:
        print("no validation split: 'nnfmu train' carves one out of train (--valid-fraction here fixes it once)")
    for note in ds.source.get("notes", []):
        print(f"note: {note}")
    if "caveat" in ds.source:
        print(f"caveat: {ds.source['caveat']}")
    return 0
