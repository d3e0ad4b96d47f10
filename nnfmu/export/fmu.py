"""The one FMU builder: any :class:`nnfmu.system.CasadiModel` -> a standalone-C co-simulation FMU.

The FMU holds CasADi-generated C for ``init`` and ``step`` (``model_casadi.c``)
and nnfmu's hand-written FMI wrapper (``templates/``: one shared core, FMI 2.0
and FMI 3.0 entry points), its sources (so that any importer can rebuild it,
e.g. ``fmpy.build.build_platform_binary``) and a binary for this platform,
compiled with the system C compiler, or for several (``platforms``: the others
cross-compiled with Zig, :mod:`nnfmu.export.platforms`). A continuous-time model
also gets Model Exchange (:mod:`nnfmu.export.model_exchange`). Every FMU of an FMI
version gets the same template files: one core for both interfaces, as in the FMI
Reference FMUs; only the generated code (``model_casadi.c``, ``model_me_casadi.c``,
``nnfmu_model.h``) differs. No Python, no libtorch inside.

Behaviour of the FMU (the reference is docs/fmu.md; the C side is ``templates/nnfmu_core.h``):

- variables: the spec's inputs (names, units, descriptions, ``min``/``max``
  where the spec's Variables give a valid range) and outputs, a fixed
  parameter ``<y>_start`` per output (the initial output y0), the spec's
  parameters as tunable parameters (they feed the ``p`` port at every sample),
  ``Ts`` as a constant, the tunable parameters ``max_samples_per_step`` and
  ``input_range_error``, and ``DefaultExperiment stepSize = Ts``;
- time is counted in whole samples from the start time; ``doStep(t, h)``
  accepts any ``h > 0`` and advances every sample instant in ``(t, t + h]``
  with the inputs held, up to ``max_samples_per_step`` samples per call;
- an input outside its valid range gives a Warning (an Error with
  ``input_range_error = true``); non-finite values give an Error, and the step
  is not taken; FMU states (also into a fresh instance), reset and several
  instances side by side work; calls the FMI state machine forbids are Errors;
- the listed sources build without libm at link time (``templates/nnfmu_libm.h``),
  so fmpy's ``build_platform_binary`` or a plain ``cc -shared -fPIC`` over
  them gives a binary that loads in any importer.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import shutil
import uuid
import zipfile
from dataclasses import dataclass
from importlib import resources
from os import PathLike
from pathlib import Path
from typing import Callable, Sequence

from nnfmu.atomic import write_atomic
from nnfmu.errors import ConfigError, FmuBuildError
from nnfmu.export import c_header, codegen, model_description
from nnfmu.export import model_exchange as _model_exchange
from nnfmu.export import platforms as _platforms
from nnfmu.export.compiler import PROFILE_FLAGS
from nnfmu.system import CasadiModel
from nnfmu.tempdirs import private_temp_dir

#: Compiled, in this order; model_casadi.c and model_me_casadi.c are not listed: nnfmu_model.c and
#: nnfmu_me_model.c include them (see nnfmu_libm.h).
CORE_SOURCES = ("nnfmu_model.c", "nnfmu_me_model.c", "nnfmu_log.c", "nnfmu_core.c", "nnfmu_variables.c",
                "nnfmu_step.c", "nnfmu_state.c", "nnfmu_me.c", "nnfmu_libm.c")
#: The core: every FMU gets these files.
TEMPLATES = ("nnfmu_core.h", "nnfmu_instance.h", "nnfmu_libm.h", *CORE_SOURCES)
#: nnfmu's own build links libm, so the model code calls it directly.
OWN_BUILD_DEFINES = ("-DNNFMU_LINKS_LIBM",)
#: Each FMI version's entry points, co-simulation and Model Exchange alike.
WRAPPER = {2: ("nnfmu_fmi2.h", "nnfmu_fmi2.c", "nnfmu_fmi2_me.c"),
           3: ("nnfmu_fmi3.h", "nnfmu_fmi3.c", "nnfmu_fmi3_me.c", "nnfmu_fmi3_unsupported.c")}
FMI_HEADERS = {2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
               3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")}


@dataclass(frozen=True, kw_only=True)
class BuildOptions:
    """How the FMU's binary is compiled.

    Attributes
    ----------
    compiler : str or None
        C compiler command; default ``$CC``, else cc, gcc or clang on PATH.
    target_isa : str or None
        ``-march`` value for the whole binary, e.g. ``"x86-64-v3"`` or ``"native"``.
        Default None: the compiler's portable baseline, with the model functions
        dispatched at load time to clones for the instruction sets the CPU has (x86-64
        Linux), which is nearly as fast and runs on any x86-64 machine.
    profile : {"fast", "exact"}
        "fast" (default): FMA contraction, vectorised exp/tanh, weights in row panels and
        AVX2+FMA / AVX-512 clones; agrees with torch to a documented tolerance. "exact": the
        same bits as CasADi's own evaluation. See docs/fmu-speed.md and :mod:`nnfmu.export.codegen`.
    precision : {"float64", "float32"}
        What the step computes in; the FMU's variables are float64 either way.
    flags : tuple of str or None
        Compiler flags before ``-march``; default the profile's, see
        :data:`nnfmu.export.compiler.PROFILE_FLAGS`.
    speed_patch : bool
        Rewrite CasADi's dense matrix-product code for speed (see :mod:`nnfmu.export.codegen`).
        False keeps CasADi's code as generated, for comparison only.
    """

    compiler: str | None = None
    target_isa: str | None = None
    profile: str = "fast"
    precision: str = "float64"
    flags: tuple[str, ...] | None = None
    speed_patch: bool = True

    def __post_init__(self) -> None:
        codegen.check_options(self.profile, self.precision)
        if self.flags is None:
            object.__setattr__(self, "flags", PROFILE_FLAGS[self.profile])
        if isinstance(self.flags, str) or not all(isinstance(f, str) for f in self.flags):
            raise ConfigError(f"BuildOptions.flags must be a sequence of strings, got {self.flags!r}")
        object.__setattr__(self, "flags", tuple(self.flags))

    def compile_flags(self) -> list[str]:
        return [*self.flags, *([f"-march={self.target_isa}"] if self.target_isa else [])]


def platform_folder(fmi_version: int) -> str:
    """``binaries/<folder>`` for this machine: FMI 2 names (linux64, ...) or FMI 3 platform tuples."""
    return _platforms.host_platform().folder(fmi_version)


def fmi_header_dir() -> Path:
    """fmpy ships the official FMI 2 and 3 headers; the FMU's sources carry copies of them."""
    import fmpy

    return Path(fmpy.__file__).parent / "c-code"


def _write_sources(model: CasadiModel, fmi_version: int, sources: Path, options: BuildOptions, with_me: bool):
    """Generate and copy every C file into ``sources``; return the description and the C files to compile.

    ``with_me``: add the Model Exchange interface of ``model.continuous`` (:mod:`nnfmu.export.model_exchange`);
    without it the same templates make a co-simulation-only FMU.
    """
    sources.mkdir(parents=True)
    prefix = codegen.symbol_prefix(model)
    code = codegen.generate_c(model, sources, prefix, speed_patch=options.speed_patch, profile=options.profile,
                              precision=options.precision)
    structure = None
    if with_me:
        _model_exchange.generate_c(model, sources, prefix, speed_patch=options.speed_patch, profile=options.profile)
        structure = _model_exchange.continuous_structure(model)
    else:
        _model_exchange.generate_no_ode(sources)
    templates = resources.files("nnfmu.export") / "templates"
    for name in (*TEMPLATES, *WRAPPER[fmi_version]):
        (sources / name).write_text((templates / name).read_text(encoding="utf-8"), encoding="utf-8")
    for name in FMI_HEADERS[fmi_version]:
        shutil.copyfile(fmi_header_dir() / name, sources / name)
    token = "{" + str(uuid.UUID(hashlib.sha256((prefix + str(fmi_version)).encode()).hexdigest()[:32])) + "}"
    stamp = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat().replace("+00:00", "Z")
    desc = model_description.describe(model.spec, token, stamp, fmi_version, structure=structure)
    (sources / "nnfmu_model.h").write_text(c_header.render_c_header(desc, code.n_x, dict(code.entry_points)),
                                           encoding="utf-8")
    return desc, [*CORE_SOURCES, *(f for f in WRAPPER[fmi_version] if f.endswith(".c"))]


def _write_fmu_tree(model: CasadiModel, fmi_version: int, root: Path, options: BuildOptions, with_me: bool,
                    targets: Sequence[_platforms.Platform], on_binary: Callable[[str, float], None] | None) -> None:
    desc, c_files = _write_sources(model, fmi_version, root / "sources", options, with_me)
    if fmi_version == 2:
        xml = model_description.render_fmi2(desc, c_files)
    else:
        xml = model_description.render_fmi3(desc)
        (root / "sources" / "buildDescription.xml").write_text(
            model_description.render_build_description(desc, c_files), encoding="utf-8")
    (root / "modelDescription.xml").write_text(xml, encoding="utf-8")
    _platforms.build_binaries(root, desc.model_identifier, [root / "sources" / f for f in c_files], fmi_version,
                             targets, host_flags=[*options.compile_flags(), *OWN_BUILD_DEFINES],
                             cross_flags=[*options.flags, *OWN_BUILD_DEFINES], compiler_command=options.compiler,
                             on_binary=on_binary)


def _zip_tree(root: Path, archive: Path) -> None:
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(root.rglob("*")):
            if path.is_file():
                zf.write(path, path.relative_to(root).as_posix())


def build_fmu(model: CasadiModel, out: str | PathLike, *, fmi_version: int = 2,
              options: BuildOptions | None = None, model_exchange: bool = True,
              platforms: str | Sequence[str] | None = None,
              on_binary: Callable[[str, float], None] | None = None) -> Path:
    """Write ``model`` as a co-simulation FMU to ``out`` (with Model Exchange for a continuous-time model).

    Parameters
    ----------
    model : CasadiModel
        ``init(y0[n_y], u0[n_u](, p[n_p])) -> x0`` and ``step(x, u(, p)) -> (x_next, y_next)``
        with its :class:`nnfmu.system.SystemSpec` (name = modelIdentifier, Ts in s, variables).
    out : path
        The ``.fmu`` file to write. It is written to a temporary file next to it and renamed,
        so a failed build leaves nothing at ``out`` (and an existing file untouched).
    fmi_version : {2, 3}
        FMI 2.0 (default: every importer reads it) or FMI 3.0 co-simulation.
    options : BuildOptions, optional
        Compiler, flags and target instruction set.
    model_exchange : bool
        For a model with ``continuous`` dynamics (physics, derivative-corrected hybrids), also offer
        Model Exchange (the ODE, with directional derivatives; docs/fmu-platforms.md). False, or a
        discrete-time model: co-simulation only.
    platforms : str or sequence of str, optional
        The binaries to ship: names as FMI 2 or 3 spells them (``"linux64,win64,darwin64,aarch64-linux,
        aarch64-darwin"``), ``"all"``, or None/``"host"``: this machine's only (see
        :mod:`nnfmu.export.platforms`; others are cross-compiled with the ``ziglang`` package).
    on_binary : callable, optional
        Called as ``on_binary(folder, seconds)`` after each binary is compiled.

    Raises
    ------
    FmuBuildError
        CasADi cannot generate C, no compiler is found, or compiling fails (with the compiler's stderr).
    ConfigError
        ``fmi_version`` is not 2 or 3.
    """
    if not isinstance(model, CasadiModel):
        raise TypeError(f"build_fmu expects an nnfmu.system.CasadiModel, got {type(model).__name__}; "
                        f"wrap your (init, step) Functions as CasadiModel(init, step, spec)")
    if fmi_version not in WRAPPER:
        raise ConfigError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    options = options or BuildOptions()
    targets = _platforms.parse_platforms(platforms)
    model_description.check_spec(model.spec)
    out = Path(out)
    if out.suffix.lower() != ".fmu":
        raise ConfigError(f"the output file must end in .fmu, got {str(out)!r}; e.g. {out.stem}.fmu")
    if out.is_dir():
        raise FmuBuildError(f"{str(out)!r} is a folder; pass the path of the .fmu file to write")
    if not out.parent.is_dir():
        problem = "is a file, not a folder" if out.parent.exists() else "does not exist; create it first"
        raise FmuBuildError(f"cannot write {out}: the folder {str(out.parent)!r} for the FMU {problem}")
    with private_temp_dir("nnfmu-build-") as tmp:  # its pid in the name: a later build removes it if killed
        _write_fmu_tree(model, fmi_version, Path(tmp) / "fmu", options, model_exchange and model.continuous is not None,
                        targets, on_binary)
        write_atomic(out, lambda partial: _zip_tree(Path(tmp) / "fmu", partial))
    return out
