"""C compilers for the FMU binaries, and a reader of a Windows DLL's export table.

Linux x86-64 binaries are built with the toolkit's C compiler (``$CC``, else cc or gcc);
win64 binaries with Debian's MinGW-w64 cross-compiler (``x86_64-w64-mingw32-gcc``,
package ``gcc-mingw-w64-x86-64``) when it is installed. Every compiler of one FMU runs
at the same time (one process each). Only the FMI functions are exported from the
binary (``-fvisibility=hidden``; CasADi's own symbols are not marked for export).
"""

from __future__ import annotations

import shutil
import struct
import time
from dataclasses import dataclass
from pathlib import Path

from ..._util._compiled import compiler
from .._errors import ExportError

__all__ = ["Target", "targets", "build_all", "pe_exports", "MINGW", "BuildClock"]

MINGW = "x86_64-w64-mingw32-gcc"
INCLUDE = Path(__file__).with_name("_include")


@dataclass(frozen=True)
class Target:
    """A platform an FMU binary is built for.

    Attributes
    ----------
    key : str
        ``linux64`` or ``win64``.
    compiler : str
        Path of the C compiler.
    suffix : str
        ``.so`` or ``.dll``.
    fmi2_dir, fmi3_dir : str
        The platform folder under ``binaries/`` in FMI 2.0 and FMI 3.0.
    """

    key: str
    compiler: str
    suffix: str
    fmi2_dir: str
    fmi3_dir: str

    def command(self, sources, out: Path, include_dirs=()) -> list[str]:
        """The compile-and-link command line for a shared library ``out``."""
        cmd = [self.compiler, "-O2", "-shared", "-fvisibility=hidden", "-DCASADI_SYMBOL_EXPORT=", "-w"]
        if self.key == "linux64":
            cmd.append("-fPIC")
        else:
            cmd += ["-static-libgcc"]
        cmd += [f"-I{d}" for d in (INCLUDE, *include_dirs)]
        cmd += [str(s) for s in sources] + ["-o", str(out), "-lm"]
        return cmd


def targets(platforms=("linux64", "win64")) -> list[Target]:
    """The targets of ``platforms`` whose compiler is installed.

    ``linux64`` is required: without a host C compiler the export is refused
    (ExportError); ``win64`` is skipped when MinGW-w64 is absent.

    Parameters
    ----------
    platforms : sequence of str
        ``linux64`` and/or ``win64``.
    """
    out = []
    for key in platforms:
        if key == "linux64":
            cc = compiler()
            if cc is None:
                raise ExportError("FMU export needs a C compiler (gcc or $CC) to build the linux64 binary")
            out.append(Target("linux64", cc, ".so", "linux64", "x86_64-linux"))
        elif key == "win64":
            cc = shutil.which(MINGW)
            if cc:
                out.append(Target("win64", cc, ".dll", "win64", "x86_64-windows"))
        else:
            raise ExportError(f"platform '{key}' unknown; choose linux64 or win64")
    return out


class BuildClock:
    """Wall time and CPU time (this process and its finished child processes, i.e. the
    compilers) since creation: the CPU time does not grow when other work shares the
    machine, the wall time does."""

    def __init__(self):
        self.t0, self.cpu0 = time.perf_counter(), self._cpu()

    @staticmethod
    def _cpu() -> float:
        t = time.process_time()
        try:
            import resource

            ru = resource.getrusage(resource.RUSAGE_CHILDREN)
            t += ru.ru_utime + ru.ru_stime
        except ImportError:  # Windows: the compilers' time is not counted
            pass
        return t

    def times(self) -> dict:
        """``build_time`` (wall, s) and ``build_cpu_time`` (s)."""
        return {"build_time": time.perf_counter() - self.t0, "build_cpu_time": self._cpu() - self.cpu0}


def build_all(jobs: list[tuple[Target, list, Path]], include_dirs=()) -> float:
    """Compile every ``(target, sources, output)`` job in parallel; returns the wall time.

    Parameters
    ----------
    jobs : list of tuple
        ``(Target, source paths, output path)``.
    include_dirs : sequence of path
        Extra include folders (the FMI headers are always on the path).
    """
    from ..._util._compiled import run_compilers

    t0 = time.perf_counter()
    failed = []
    for t, (code, log) in zip([j[0] for j in jobs], run_compilers([t.command(src, out, include_dirs)
                                                                  for t, src, out in jobs]), strict=True):
        if code != 0:
            first = next((line for line in log.splitlines() if "error" in line), log.strip()[:200])
            failed.append(f"{t.key} ({Path(t.compiler).name}): {first}")
    if failed:
        raise ExportError("compiling the FMU binary failed: " + "; ".join(failed))
    return time.perf_counter() - t0


def pe_exports(path) -> list[str]:
    """Names exported by a Windows PE/COFF DLL (its export directory), read directly.

    Parameters
    ----------
    path : str or Path
        The ``.dll``.
    """
    data = Path(path).read_bytes()
    if data[:2] != b"MZ":
        raise ValueError(f"{path}: not a PE file")
    pe = struct.unpack_from("<I", data, 0x3C)[0]
    if data[pe : pe + 4] != b"PE\0\0":
        raise ValueError(f"{path}: no PE signature")
    n_sections, opt_size = struct.unpack_from("<H", data, pe + 6)[0], struct.unpack_from("<H", data, pe + 20)[0]
    opt = pe + 24
    magic = struct.unpack_from("<H", data, opt)[0]
    dirs = opt + (112 if magic == 0x20B else 96)  # PE32+ or PE32
    export_rva = struct.unpack_from("<I", data, dirs)[0]
    if export_rva == 0:
        return []
    sections = []
    for k in range(n_sections):
        s = opt + opt_size + 40 * k
        vsize, va, rsize, raw = struct.unpack_from("<IIII", data, s + 8)
        sections.append((va, max(vsize, rsize), raw))

    def offset(rva):
        for va, size, raw in sections:
            if va <= rva < va + size:
                return rva - va + raw
        raise ValueError(f"{path}: RVA {rva:#x} outside every section")

    e = offset(export_rva)
    n_names, _, names_rva = struct.unpack_from("<III", data, e + 24)
    names_off = offset(names_rva)
    out = []
    for k in range(n_names):
        name_off = offset(struct.unpack_from("<I", data, names_off + 4 * k)[0])
        out.append(data[name_off : data.index(b"\0", name_off)].decode("ascii"))
    return out
