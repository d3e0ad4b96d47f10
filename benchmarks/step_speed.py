"""FMU step speed against this machine's ceilings, all measured in one run (issue 14).

Builds FMUs of networks with random (seeded) weights, 2 inputs and 2 outputs,
in three builds each: ``exact`` (the same bits as CasADi), ``fast`` (the
default: FMA, vectorised exp/tanh, weights in row panels) and ``fast f32``
(``--precision float32``). Cases: the GRU at hidden 16-256, the other
architectures at their defaults (hidden 32) and the TCN at width 64; and what
the defaults give users (:func:`user_cases`, issue 36; ``--no-users`` leaves
them out): a default training's FMU (two GRU-32 on a linear path) with 1 and 3
outputs beside one of its members and the plain GRU-32 of the same ports, a
search's mixed ensemble, an init-window FMU and a hybrid. Every case is printed
against its weight-read bound, and the issue-36 targets (a member within 1.2x of
the plain network, two members within 2.2x of one) with the figures of the run.
Measured, all in process CPU time on one pinned core (``taskset``), in
``--rounds`` rounds that interleave every case (the median is printed):

- each FMU's step in C: ``c/fmu_step_driver.c`` dlopens the binary and loops
  fmi2SetReal + fmi2DoStep(Ts) + fmi2GetReal, 3500 steps, after a warm-up run
  (each round's figure is the least of 3 runs in one process: the run other
  processes disturbed least);
- the peak of the core: independent chains of AVX2 FMA, AVX2 multiply + add
  (what a build without FMA executes) and AVX-512 FMA (``c/peak.c``);
- the read bandwidth from the cache that holds each network's weights: a step
  reads every weight once (4 bytes per FLOP in double, 2 in float), so
  ``bandwidth / bytes-per-FLOP`` bounds the GFLOP/s as well as the FMA peak;
- the hand-written C GRU-64 (``c/gru_hand.c``) as a yardstick, and with
  ``--torch`` the torch eager step of the GRU-64 (batch 1, float32).

FLOPs per step are 2 per weight (each weight is used once per step; for the
GRU 2*3h(h + n_y + n_u) + 2*n_y*h). Export time is the CPU time of
``build_fmu`` (code generation, compile, zip) per FMU, and of the command line
once end to end.

    python benchmarks/step_speed.py [--sizes 16 32 64 128 256] [--archs mlp rnn lstm tcn] [--rounds 7]
                                    [--core 1] [--torch] [--json results.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np
import torch

from nnfmu.export import casadi_model
from nnfmu.export.step_cost import function_cost
from nnfmu.cbuild import run_compiler
from nnfmu.export.compiler import PROFILE_FLAGS
from nnfmu.export.fmu import BuildOptions, build_fmu, fmi_header_dir, platform_folder
from nnfmu.models import EnsembleStepModel, ModelConfig, build_model, save_checkpoint

HERE = Path(__file__).parent
META = {"name": "bench", "Ts": 0.01, "inputs": [{"name": "u1", "unit": ""}, {"name": "u2", "unit": ""}],
        "outputs": [{"name": "y1", "unit": ""}, {"name": "y2", "unit": ""}]}
BUILDS = {"exact": BuildOptions(profile="exact"), "fast": BuildOptions(),
          "fast f32": BuildOptions(precision="float32")}
PEAKS = ("fma256", "muladd256", "fma512")


def make_network(arch: str, hidden: int, seed: int = 0):
    torch.manual_seed(seed)
    return build_model(ModelConfig(arch=arch, n_u=2, n_y=2, hidden=hidden), dict(META, name=f"{arch}{hidden}")).eval()


def n_weights(network) -> int:
    """Weights the step's matrix products read: every matrix (and Conv1d kernel), those of an ensemble's every member
    and of a linear path; a hybrid's network counts once per RK4 stage (:mod:`nnfmu.export.step_cost`)."""
    return function_cost(casadi_model(network).step).weights


def ports(n_u: int, n_y: int, name: str) -> dict:
    return {"name": name, "Ts": 0.01, "inputs": [{"name": f"u{i + 1}", "unit": ""} for i in range(n_u)],
            "outputs": [{"name": f"y{i + 1}", "unit": ""} for i in range(n_y)]}


def on_path(arch: str, hidden: int, n_u: int, n_y: int, order: int, seed: int, **options):
    """A network on a linear path of ``order`` states, its path and correction random (small, stable) and seeded."""
    torch.manual_seed(seed)
    config = ModelConfig(arch=arch, n_u=n_u, n_y=n_y, hidden=hidden, linear_order=order, **options)
    model = build_model(config, ports(n_u, n_y, f"{arch}{hidden}_path")).eval()
    with torch.no_grad():
        for name, t in [*model.named_parameters(), *model.named_buffers()]:
            if name.startswith(("lin_", "alpha")):
                t.normal_(0, 0.3 / order ** 0.5)
    return model


def plain(n_u: int, n_y: int, hidden: int = 32):
    torch.manual_seed(0)
    return build_model(ModelConfig(arch="gru", n_u=n_u, n_y=n_y, hidden=hidden), ports(n_u, n_y, "plain")).eval()


def user_cases() -> dict:
    """What the defaults give users (issue 36): a default training's FMU (two GRU-32 on a linear path) with 1 and 3
    outputs, one member of it and the plain GRU-32 of the same ports; a search's mixed ensemble (LSTM-64 + GRU-32);
    a GRU-32 with an init window of 10; the hybrid valve (GRU-32 correction inside RK4)."""
    from nnfmu.hybrid import HybridConfig

    cases = {}
    for n_y, order in ((1, 2), (3, 6)):
        members = [on_path("gru", 32, 1, n_y, order, seed) for seed in (0, 1)]
        cases.update({f"plain-{n_y}y": plain(1, n_y), f"member-{n_y}y": members[0],
                      f"default-{n_y}y": EnsembleStepModel.from_members(members)})
    cases["search"] = EnsembleStepModel.from_members([on_path("lstm", 64, 1, 1, 2, 2), on_path("gru", 32, 1, 1, 2, 3)])
    cases["initwin"] = on_path("gru", 32, 1, 1, 2, 4, init_window=10)
    torch.manual_seed(5)
    hybrid = build_model(HybridConfig(n_u=2, n_y=2, physics="valve", hidden=32)).eval()
    with torch.no_grad():  # the correction starts at zero, which CasADi would fold away
        for prm in hybrid.correction.parameters():
            prm.normal_(0, 0.1)
    cases["hybrid"] = hybrid
    return cases


def pinned(core: int, command: list[str]) -> str:
    return subprocess.run(["taskset", "-c", str(core), *command], capture_output=True, text=True,
                          check=True).stdout.strip()


def compile_programs(work: Path) -> dict[str, Path]:
    progs = {"driver": (HERE / "c" / "fmu_step_driver.c", [fmi_header_dir()]), "peak": (HERE / "c" / "peak.c", [])}
    out = {}
    for name, (source, include) in progs.items():
        out[name] = work / name
        run_compiler(["-O3", "-std=c99", *(f"-I{d}" for d in include), str(source), "-o", str(out[name]), "-lm",
                      "-ldl"], what=f"compiling {source.name}")
    return out


def fmu_command(fmu: Path, driver: Path, steps: int) -> list[str]:
    import fmpy

    md = fmpy.read_model_description(str(fmu))
    folder = fmu.with_suffix("")
    zipfile.ZipFile(fmu).extractall(folder)
    lib = folder / "binaries" / platform_folder(2) / f"{md.coSimulation.modelIdentifier}.so"
    vrs = {c: ",".join(str(v.valueReference) for v in md.modelVariables if v.causality == c)
           for c in ("input", "output")}
    return [str(driver), str(lib), md.guid, repr(float(md.defaultExperiment.stepSize)), str(steps),
            vrs["input"], vrs["output"]]


def hand_gru_commands(network, work: Path, steps: int) -> dict[str, list[str]]:
    """The hand-written C GRU at the exact profile's flags and at the fast ones with -march=x86-64-v3."""
    write_gru_weights(network, work / "gru_weights.h")
    commands = {}
    for label, flags in (("hand C", PROFILE_FLAGS["exact"]), ("hand C v3 fma", (*PROFILE_FLAGS["fast"],
                                                                                  "-march=x86-64-v3"))):
        exe = work / label.replace(" ", "_")
        run_compiler([*flags, f"-I{work}", str(HERE / "c" / "gru_hand.c"), "-o", str(exe), "-lm"],
                     what="compiling gru_hand.c")
        commands[label] = [str(exe), str(steps)]
    return commands


def write_gru_weights(network, path: Path) -> None:
    """gru_weights.h for gru_hand.c: the network's weights column-major, in float64."""
    sd = {k: v.detach().double().numpy() for k, v in network.state_dict().items()}
    arrays = {"W_ih": sd["rnn_layers.0.weight_ih_l0"], "W_hh": sd["rnn_layers.0.weight_hh_l0"],
              "b_ih": sd["rnn_layers.0.bias_ih_l0"], "b_hh": sd["rnn_layers.0.bias_hh_l0"],
              "W_o": sd["readout.weight"], "b_o": sd["readout.bias"], "u_mean": sd["u_mean"],
              "u_std": sd["u_std"], "y_mean": sd["y_mean"], "y_std": sd["y_std"]}
    c = network.config
    lines = [f"#define NY {c.n_y}", f"#define NU {c.n_u}", f"#define H {c.hidden}",
             f"#define SKIP_SCALE {c.skip_scale if c.skip else 0.0!r}"]
    for name, a in arrays.items():
        flat = np.asarray(a, dtype=float).reshape(a.shape[0], -1).ravel(order="F")
        lines.append(f"static const double {name}[{flat.size}] = {{{', '.join(repr(float(v)) for v in flat)}}};")
    path.write_text("\n".join(lines) + "\n")


def torch_us_per_step(network, steps: int, core: int) -> float:
    """Eager ``model.step`` loop at batch 1 in float32, process CPU time, on ``core``."""
    os.sched_setaffinity(0, {core})
    u = torch.tensor([[np.sin(0.01 * k * (i + 1)) * (1 + 0.5 * i) for i in range(2)] for k in range(steps)],
                     dtype=torch.float32)
    with torch.no_grad():
        x = network.init(torch.zeros(1, 2), u[:1])
        t0 = time.process_time()
        for k in range(steps):
            x, _ = network.step(x, u[k:k + 1])
        return (time.process_time() - t0) / steps * 1e6


def cli_export_seconds(network, work: Path, profile: str) -> tuple[float, float]:
    """Wall and CPU seconds of ``python -m nnfmu.export`` for ``network`` (process start-up included)."""
    ckpt = save_checkpoint(work / f"cli_{profile}.pt", network)
    before = os.times()
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "nnfmu.export", str(ckpt), "-o", str(work / f"cli_{profile}.fmu"),
                    "--profile", profile], check=True, capture_output=True)
    after = os.times()
    return time.perf_counter() - t0, (after.children_user - before.children_user) + (
        after.children_system - before.children_system)


def cpu_seconds() -> float:
    """CPU time of this process and its finished children (the compiler), in s."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def parse(output: str) -> tuple[float, str]:
    """``key=value`` output of the C programs -> (number, rest)."""
    if output == "unsupported":
        return float("nan"), ""
    first, *rest = output.split()
    return float(first.split("=")[1]), " ".join(rest)


def build_cases(args, work: Path) -> tuple[dict, dict]:
    """FMUs of every case and build: ``{(case, build): path}``, and per case its network."""
    cases = {f"gru{h}": make_network("gru", h) for h in args.sizes}
    cases.update({f"{arch}32": make_network(arch, 32) for arch in args.archs})
    if "tcn" in args.archs:
        cases["tcn64"] = make_network("tcn", 64)
    if args.users:
        cases.update(user_cases())
    fmus, export_s = {}, {}
    for name, network in cases.items():
        model = casadi_model(network)
        for build, options in BUILDS.items():
            path = work / f"{name}_{build.replace(' ', '_')}.fmu"
            t0 = cpu_seconds()
            fmus[name, build] = build_fmu(model, path, options=options)
            export_s[name, build] = cpu_seconds() - t0
    return cases, {"fmus": fmus, "export_s": export_s}


def measure(args, work: Path, programs: dict, cases: dict, fmus: dict) -> tuple[dict, dict]:
    """Median over interleaved rounds of every job's figure, and each FMU's final outputs."""
    jobs = {key: fmu_command(path, programs["driver"], args.steps) for key, path in fmus.items()}
    if "gru64" in cases:
        jobs.update(hand_gru_commands(cases["gru64"], work, args.steps))
    jobs.update({("peak", mode): [str(programs["peak"]), mode] for mode in PEAKS})
    for name, network in cases.items():
        for bytes_per_weight in (8, 4):
            size = n_weights(network) * bytes_per_weight
            jobs[("read", size)] = [str(programs["peak"]), "read", str(size)]
    samples: dict = {key: [] for key in jobs}
    finals: dict = {}
    keys = list(jobs)
    for r in range(args.rounds):
        for key in keys[r % len(keys):] + keys[:r % len(keys)]:  # rotate the order from round to round
            value, rest = parse(pinned(args.core, jobs[key]))
            samples[key].append(value)
            finals[key] = rest
    return {key: statistics.median(v) for key, v in samples.items()}, finals


def report(args, cases, built, median, finals, extra) -> dict:
    fma, muladd, fma512 = (median[("peak", m)] for m in PEAKS)
    print(f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}; core {args.core}; median of "
          f"{args.rounds} interleaved rounds, process CPU time")
    print(f"peak GFLOP/s: AVX2 FMA {fma:.1f}, AVX2 mul+add (no FMA) {muladd:.1f}, AVX-512 FMA "
          + ("not supported by this CPU" if np.isnan(fma512) else f"{fma512:.1f}"))
    print(f"\n{'case':<8}{'weights':>9}{'exact us':>10}{'fast us':>9}{'f32 us':>8}{'fast/exact':>11}"
          f"{'f32 gain':>9}{'GFLOP/s':>9}{'% FMA':>7}{'% bound':>8}{'f32 GF/s':>9}{'% bound':>8}"
          f"{'export CPU s exact/fast':>25}")
    rows = {}
    for name, network in cases.items():
        w = n_weights(network)
        us = {b: median[(name, b)] for b in BUILDS}
        gf = {b: 2 * w / us[b] * 1e-3 for b in BUILDS}
        single = {b: b == "fast f32" for b in BUILDS}  # float32: twice the FLOPs per FMA, half the bytes per FLOP
        bound = {b: min(fma * (2 if single[b] else 1), median[("read", w * (4 if single[b] else 8))] /
                        (2 if single[b] else 4)) for b in BUILDS}
        rows[name] = {"weights": w, "us": us, "gflops": gf, "bound_gflops": bound,
                      "export_s": {b: built["export_s"][(name, b)] for b in BUILDS}}
        print(f"{name:<8}{w:>9}{us['exact']:>10.3f}{us['fast']:>9.3f}{us['fast f32']:>8.3f}"
              f"{us['exact'] / us['fast']:>11.2f}{us['fast'] / us['fast f32']:>9.2f}{gf['fast']:>9.1f}"
              f"{100 * gf['fast'] / fma:>7.0f}{100 * gf['fast'] / bound['fast']:>8.0f}{gf['fast f32']:>9.1f}"
              f"{100 * gf['fast f32'] / bound['fast f32']:>8.0f}"
              f"{built['export_s'][(name, 'exact')]:>19.2f} / {built['export_s'][(name, 'fast')]:.2f}")
    print("  % FMA: of the AVX2 FMA peak (double); % bound: of min(FMA peak, read bandwidth of the weights / bytes "
          "per FLOP), in float32 twice the peak and half the bytes")
    for name in rows:
        y = {b: np.array([float(v) for v in finals[(name, b)].split("=")[1].split(",")]) for b in BUILDS}
        scale = np.abs(y["exact"]).max()
        rows[name]["y_rel_diff"] = {b: float(np.abs(y[b] - y["exact"]).max() / scale) for b in ("fast", "fast f32")}
    worst = {b: max(r["y_rel_diff"][b] for r in rows.values()) for b in ("fast", "fast f32")}
    print(f"final outputs after {args.steps} steps, largest relative difference to exact: fast {worst['fast']:.1e}, "
          f"fast f32 {worst['fast f32']:.1e}")
    for label in ("hand C", "hand C v3 fma"):
        if label in median:
            print(f"hand-written C GRU-64 ({label}): {median[label]:.3f} us")
    for label, value in extra.items():
        print(f"{label}: {value}")
    return {"peak_gflops": {"avx2_fma": fma, "avx2_mul_add": muladd, "avx512_fma": fma512}, "cases": rows,
            "load": os.getloadavg(), **extra}


def targets(rows: dict, peak: float) -> None:
    """The issue's targets, each with the figure measured in this run."""
    def line(ok: bool, text: str) -> None:
        print(f"  [{'met' if ok else 'NOT met'}] {text}")

    print("\ntargets (issue 14):")
    if "gru64" in rows:
        us = rows["gru64"]["us"]["fast"]
        line(us <= 1.2, f"GRU-64 float64 step <= 1.2 us: {us:.3f} us")
    for name in (n for n in ("gru64", "gru128", "gru256") if n in rows):
        share = rows[name]["gflops"]["fast"] / peak
        line(share >= 0.4, f"{name} float64 >= 40 % of the AVX2 FMA peak: {100 * share:.0f} %")
    for name in (n for n in ("gru64", "gru128", "gru256") if n in rows):
        gain = rows[name]["us"]["fast"] / rows[name]["us"]["fast f32"]
        line(gain >= 1.8, f"{name} float32 >= 1.8x faster than float64: {gain:.2f}x")
    if "tcn64" in rows and "gru64" in rows:
        tcn, gru = rows["tcn64"]["us"]["fast"], rows["gru64"]["us"]["fast"]
        line(tcn <= gru, f"TCN-64 no slower than GRU-64: {tcn:.3f} vs {gru:.3f} us ({rows['tcn64']['weights']} "
                         f"vs {rows['gru64']['weights']} weights)")
    if "tcn32" in rows:
        line(rows["tcn32"]["us"]["fast"] <= 1.5, f"TCN default <= 1.5 us: {rows['tcn32']['us']['fast']:.3f} us")
    if any(name.startswith("default-") for name in rows):
        print("targets (issue 36), fast and float32 builds:")
    for n_y in (n for n in (1, 3) if f"default-{n}y" in rows):
        us = {k: rows[f"{k}-{n_y}y"]["us"] for k in ("plain", "member", "default")}
        for b in ("fast", "fast f32"):
            ratio = us["member"][b] / us["plain"][b]
            line(ratio <= 1.2, f"{n_y} output(s), {b}: a default member within 1.2x of the plain GRU-32: {ratio:.2f}x "
                               f"({us['member'][b]:.3f} vs {us['plain'][b]:.3f} us)")
            ratio = us["default"][b] / us["member"][b]
            line(ratio <= 2.2, f"{n_y} output(s), {b}: the two-member default within 2.2x of one member: {ratio:.2f}x "
                               f"({us['default'][b]:.3f} us)")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", type=int, default=[16, 32, 64, 128, 256], help="GRU hidden sizes")
    parser.add_argument("--archs", nargs="*", default=["mlp", "rnn", "lstm", "tcn"],
                        choices=["mlp", "rnn", "lstm", "tcn"], help="other architectures, at hidden 32")
    parser.add_argument("--steps", type=int, default=3500)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--core", type=int, default=max(os.sched_getaffinity(0)), help="the core to pin to")
    parser.add_argument("--no-users", dest="users", action="store_false",
                        help="leave out what the defaults give users (default training, search, init window, hybrid)")
    parser.add_argument("--torch", action="store_true", help="also time torch eager for the GRU-64")
    parser.add_argument("--json", type=Path, help="also write the figures to this file")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        programs = compile_programs(work)
        cases, built = build_cases(args, work)
        extra = {}
        if "gru64" in cases:
            for profile in ("exact", "fast"):
                wall, cpu = cli_export_seconds(cases["gru64"], work, profile)
                extra[f"python -m nnfmu.export GRU-64 --profile {profile}"] = f"{wall:.2f} s wall, {cpu:.2f} s CPU"
            if args.torch:
                extra["torch eager GRU-64 step (float32, batch 1)"] = \
                    f"{torch_us_per_step(cases['gru64'], args.steps, args.core):.1f} us"
        median, finals = measure(args, work, programs, cases, built["fmus"])
        result = report(args, cases, built, median, finals, extra)
        targets(result["cases"], result["peak_gflops"]["avx2_fma"])
    if args.json:
        args.json.write_text(json.dumps(result, indent=1, default=float))


if __name__ == "__main__":
    main()
