"""The batch file (``JOBS.toml``): parsed, expanded into jobs and checked as a whole before any
work.

::

    [defaults]                  # any option of the bake command, TOML-typed
    res = 1024
    formats = "png,preview"

    [[job]]                     # one run
    mesh = "props/crate.obj"    # relative to the batch file's folder
    preset = "glass"
    impact = ["0.3,0.04,0.28:0.1d"]
    name = "crate_glass"        # the output sub-folder [the mesh's stem]

    [[job]]                     # a sweep: a glob of meshes x seeds x presets
    mesh = "rocks/*.ply"
    presets = ["mud", "crackle"]
    seeds = [1, 2, 3]
    name = "{stem}_{preset}_{seed}"   # [{stem}_{preset}_s{seed}: what the sweep varies]

Every job's options go through the bake command's own click options and then
:meth:`RunParams.validate`, so a value the command refuses is refused here with the same words
(prefixed with the job and key), and a value it accepts means the same thing.
"""

from __future__ import annotations

import glob
import hashlib
import itertools
import json
import os
import re
import string
import struct
import tomllib
from dataclasses import dataclass
from pathlib import Path

import click

from crackbake import __version__
from crackbake.errors import CrackbakeError
from crackbake.params import RunParams

#: Keys of a ``[[job]]`` that are not bake options.
JOB_KEYS = ("mesh", "name", "seeds", "presets")
#: Bake options a batch sets itself (the output folder) or that only shape the command's own
#: console output.
NOT_IN_BATCH = ("out", "quiet", "verbose", "as_json", "progress", "version", "help")
#: Files the batch writes into its output folder, so no job may take their names.
SUMMARY_FILES = ("batch.json", "batch.csv", "batch_sheet.png")
_GLOB = re.compile(r"[*?\[]")


@dataclass(frozen=True)
class Job:
    """One run of a batch.

    Attributes
    ----------
    index : int
        1-based position of its ``[[job]]`` entry in the batch file.
    name : str
        Output sub-folder name, unique in the batch.
    params : RunParams
        Validated; ``out`` is ``OUT/<name>`` and ``mesh`` an absolute path.
    argv : tuple of str
        The bake command line equal to this job (without ``-o``), for people and logs.
    """

    index: int
    name: str
    params: RunParams
    argv: tuple[str, ...]

    def input_hashes(self) -> dict:
        """SHA-256 of every input file (mesh, weight map, sidecar), the manifest's way."""
        from crackbake.exchange.manifest import inputs

        return {k: v["sha256"] for k, v in inputs(self.params).items()}

    def job_hash(self, hashes: dict | None = None) -> str:
        """What decides whether a finished folder can be kept (``--resume``): the input files'
        contents, every parameter but the output folder and input paths, the crackbake version.
        ``hashes``: :meth:`input_hashes` when already known."""
        options = self.params.to_dict()
        for key in ("out", "mesh", "cracks", "weight_map"):
            options.pop(key, None)
        doc = {"crackbake": __version__, "inputs": hashes or self.input_hashes(),
               "options": options}
        return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


class BatchFileError(CrackbakeError):
    """A batch file refused before any work (exit 2)."""


def _bake_options() -> dict[str, click.Option]:
    """Batch key -> the bake command's click option it sets: each long option without its
    dashes (``sim-faces`` or ``sim_faces``) and the option's parameter name (``impacts``)."""
    from crackbake.cli.bake import bake

    table: dict[str, click.Option] = {}
    for p in bake.params:
        if not isinstance(p, click.Option) or p.name in NOT_IN_BATCH:
            continue
        for opt in p.opts:
            if opt.startswith("--"):
                table[opt[2:].replace("-", "_")] = p
        table[p.name] = p
    return table


def _argv(key: str, value, option: click.Option, base: Path) -> list[str]:
    """The command-line words that set ``option`` to the TOML ``value``."""
    flag = next(o for o in option.opts if o.startswith("--"))
    if option.is_flag:
        if not isinstance(value, bool):
            raise ValueError(f"expected true or false, got {value!r}")
        return [flag] if value else []
    if isinstance(value, dict) and option.multiple:  # look = {color = "90,60,40"}
        value = [f"{k}={_word(v)}" for k, v in value.items()]
    if option.multiple:
        items = value if isinstance(value, list) else [value]
    elif isinstance(value, list) and option.name == "formats":
        items = [",".join(str(v) for v in value)]
    else:
        items = [value]
    words = []
    for v in items:
        if isinstance(v, bool | dict | list):
            raise ValueError(f"expected a {'list of ' if option.multiple else ''}value like "
                             f"the command line's, got {v!r}")
        text = _word(v)
        if isinstance(option.type, click.Path):
            text = str(base / os.path.expanduser(text))
        words += [flag, text]
    return words


def _word(value) -> str:
    """A TOML scalar as the command line writes it."""
    if isinstance(value, list):
        return ",".join(_word(v) for v in value)
    return repr(value) if isinstance(value, float) else str(value)


def _options_argv(options: dict, base: Path, where: str) -> tuple[list[str], dict[str, str]]:
    """``options`` (bake keys) as command-line words, and option flag -> the key that set it."""
    table = _bake_options()
    words: list[str] = []
    keys: dict[str, str] = {}
    for key, value in options.items():
        option = table.get(key.replace("-", "_"))
        if option is None:
            close = [k.replace("_", "-") for k in table if k[:3] == key.replace("-", "_")[:3]]
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise BatchFileError(f"{where}: unknown key '{key}'{hint}; use an option of the bake "
                                 "command (crackbake --help) or mesh, name, seeds, presets")
        try:
            words += _argv(key, value, option, base)
        except ValueError as exc:
            raise BatchFileError(f"{where}: key '{key}': {exc}") from None
        for o in option.opts:
            keys[o] = key
    return words, keys


def _key_of(message: str, keys: dict[str, str], where: str, defaults: dict[str, str]) -> str:
    """Where an option's error came from: ``<where>: key 'res'``, or the defaults' key."""
    for flag in re.findall(r"(?:^|[\s'(])(--[a-z][a-z0-9-]*|-[a-zA-Z])\b", message):
        if flag in keys:
            return f"{where}: key '{keys[flag]}'"
        if flag in defaults:
            file, _, job = where.partition(": ")
            return f"{file}: [defaults] key '{defaults[flag]}' (in {job})"
    return where


def _parse_run(mesh: Path, words: list[str]) -> RunParams:
    """:class:`RunParams` as the bake command builds it from ``MESH words...``."""
    from crackbake.cli.bake import CONSOLE_OPTIONS, bake, run_params

    ctx = bake.make_context("bake", [str(mesh), *words])
    options = dict(ctx.params)
    mesh = options.pop("mesh")
    for key in (*CONSOLE_OPTIONS, "out"):
        options.pop(key, None)
    options["out"] = None
    return run_params(mesh, options)


def _names(template: str, **fields) -> str:
    """The job's folder name from ``template`` (``{stem}``, ``{preset}``, ``{seed}``)."""
    known = {k for _, k, _, _ in string.Formatter().parse(template) if k}
    bad = known - set(fields)
    if bad:
        raise ValueError(f"'{{{sorted(bad)[0]}}}' is not one of "
                         f"{', '.join('{' + k + '}' for k in fields)}")
    return template.format(**fields)


def _check_name(name: str) -> None:
    if (not name.strip() or name in (".", "..") or "/" in name or "\\" in name
            or name.startswith(".") or "\0" in name):
        raise ValueError(f"'{name}' is not a folder name; use letters, digits, - and _")
    if name in SUMMARY_FILES:
        raise ValueError(f"'{name}' is the batch's own summary file; choose another name")


def _expand(entry: dict, where: str, base: Path) -> list[tuple[str, Path, dict]]:
    """``(name, mesh, extra options)`` of each run a ``[[job]]`` entry stands for (``where``
    names the entry in messages)."""
    if "mesh" not in entry:
        raise BatchFileError(f"{where}: no 'mesh' key; give the mesh file (or a glob) to crack")
    pattern = entry["mesh"]
    if not isinstance(pattern, str) or not pattern.strip():
        raise BatchFileError(f"{where}: key 'mesh': expected a file path, got {pattern!r}")
    full = base / os.path.expanduser(pattern)
    if _GLOB.search(pattern):
        meshes = [Path(p) for p in sorted(glob.glob(str(full), recursive=True))
                  if Path(p).is_file()]
        if not meshes:
            raise BatchFileError(f"{where}: key 'mesh': '{pattern}' matches no file "
                                 f"(paths are relative to {base}/)")
    else:
        if not full.is_file():
            what = "is a folder" if full.is_dir() else "not found"
            raise BatchFileError(f"{where}: key 'mesh': {pattern}: {what} "
                                 f"(relative to {base}/)")
        meshes = [full]
    sweeps = {}
    for key, option, kind in (("seeds", "seed", int), ("presets", "preset", str)):
        if key not in entry:
            continue
        if key[:-1] in entry:
            raise BatchFileError(f"{where}: keys '{key}' and '{option}' both given; keep one")
        values = entry[key]
        if (not isinstance(values, list) or not values
                or not all(isinstance(v, kind) and not isinstance(v, bool) for v in values)):
            raise BatchFileError(f"{where}: key '{key}': expected a non-empty list of "
                                 f"{'integers' if kind is int else 'names'}, got {values!r}")
        sweeps[option] = values
    swept = len(meshes) > 1 or bool(sweeps)
    template = entry.get("name")
    if template is None:
        # A swept job's folders tell its variants apart: the preset (swept or not) and the seed.
        preset = "preset" in sweeps or (swept and "preset" in entry)
        template = "{stem}" + ("_{preset}" if preset else "") + (
            "_s{seed}" if "seed" in sweeps else "")
    elif not isinstance(template, str):
        raise BatchFileError(f"{where}: key 'name': expected a folder name, got {template!r}")
    runs = []
    for mesh, preset, seed in itertools.product(
        meshes, sweeps.get("preset", [None]), sweeps.get("seed", [None])
    ):
        extra = {k: v for k, v in (("preset", preset), ("seed", seed)) if v is not None}
        try:
            name = (_names(template, stem=mesh.stem, preset=preset or entry.get("preset", ""),
                           seed=seed if seed is not None else entry.get("seed", ""))
                    if swept or "{" in template else template)
            _check_name(name)
        except ValueError as exc:
            raise BatchFileError(f"{where}: key 'name': {exc}") from None
        runs.append((name, mesh, extra))
    return runs


def load_jobs(path: str | os.PathLike, out: str | os.PathLike) -> list[Job]:
    """Every job of the batch file ``path``, writing under ``out``; checked as a whole.

    Raises
    ------
    BatchFileError
        One line naming the job and key at fault: a TOML error, an unknown key, a missing mesh,
        a value the bake command refuses, two jobs writing the same folder, a job folder
        crackbake may not replace.  Nothing has been written.
    """
    from crackbake.transaction.outdir import check_replaceable, target_dir

    path = Path(path)
    shown = path.name
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BatchFileError(f"batch file {path}: not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BatchFileError(f"batch file {path}: cannot read it ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise BatchFileError(f"{shown}: not valid TOML: {exc}") from None
    base = path.resolve().parent
    unknown = sorted(set(doc) - {"defaults", "job"})
    if unknown:
        raise BatchFileError(f"{shown}: unknown table or key '{unknown[0]}'; use [defaults] "
                             "and [[job]] entries")
    defaults = doc.get("defaults", {})
    entries = doc.get("job", [])
    if not isinstance(defaults, dict):
        raise BatchFileError(f"{shown}: 'defaults' must be a table: [defaults]")
    if not isinstance(entries, list) or not entries:
        raise BatchFileError(f"{shown}: no [[job]] entries; add one with a mesh = \"...\" key")
    for key in JOB_KEYS:
        if key in defaults:
            raise BatchFileError(f"{shown}: [defaults] key '{key}': belongs in each [[job]]")
    default_words, default_keys = _options_argv(defaults, base, f"{shown}: [defaults]")

    out = Path(out)
    jobs: list[Job] = []
    folders: dict[Path, Job] = {}
    for index, entry in enumerate(entries, 1):
        if not isinstance(entry, dict):
            raise BatchFileError(f"{shown}: [[job]] {index} is not a table")
        for name, mesh, extra in _expand(entry, f"{shown}: [[job]] {index}", base):
            where = f"{shown}: [[job]] {index} '{name}'"
            options = {k: v for k, v in entry.items() if k not in JOB_KEYS}
            options.update(extra)
            words, keys = _options_argv(options, base, where)
            try:
                params = _parse_run(mesh, default_words + words)
                folder = out / name
                # Absolute: a worker's current folder is not the driver's (on a cluster, where
                # its node's Ray was started), and a relative path would land there.
                params = RunParams(**{**params.__dict__,
                                      "out": Path(os.path.abspath(folder))}).validate()
            except click.ClickException as exc:
                from crackbake.cli.common import usage_line

                message = usage_line(exc)
                raise BatchFileError(f"{_key_of(message, keys, where, default_keys)}: "
                                     f"{message}") from None
            except CrackbakeError as exc:
                message = str(exc)
                raise BatchFileError(f"{_key_of(message, keys, where, default_keys)}: "
                                     f"{message}") from None
            job = Job(index=index, name=name, params=params,
                      argv=(str(mesh), *default_words, *words))
            final = target_dir(folder)
            if final in folders:
                other = folders[final]
                raise BatchFileError(
                    f"{where}: writes the same folder {folder}/ as [[job]] {other.index} "
                    f"'{other.name}'; give one of them another name")
            try:
                check_replaceable(final, folder)
            except CrackbakeError as exc:
                raise BatchFileError(f"{where}: {exc}") from None
            folders[final] = job
            jobs.append(job)
    return jobs


def face_count(path: str | os.PathLike) -> int:
    """The faces of a mesh file read from its header or lines, without loading it (a batch
    sizes the memory of each job before it runs); an upper estimate from the file size when the
    format has no cheap count.  Polygons count as their triangles."""
    path = Path(path)
    suffix = path.suffix.lower()
    size = path.stat().st_size
    try:
        if suffix == ".ply":
            with path.open("rb") as fh:
                for _ in range(200):
                    line = fh.readline()
                    if line.startswith(b"element face"):
                        return int(line.split()[2]) * 2  # quads and strips: up to 2 triangles
                    if line.startswith(b"end_header") or not line:
                        break
        elif suffix == ".stl":
            with path.open("rb") as fh:
                head = fh.read(84)
            if len(head) == 84 and not head.lstrip().startswith(b"solid"):
                return struct.unpack("<I", head[80:84])[0]
            return size // 200  # ASCII: about 250 bytes a facet
        elif suffix in (".obj", ".off"):
            faces = 0
            with path.open("rb") as fh:
                for line in fh:
                    if line.startswith(b"f ") or (suffix == ".off" and line[:1].isdigit()):
                        faces += max(1, len(line.split()) - 3)
            return faces
    except (OSError, ValueError, IndexError):
        pass
    return size // 12  # glTF and the rest: at most one 32-bit index triple per 12 bytes
