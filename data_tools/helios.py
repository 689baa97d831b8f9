"""Helios-grown plants: a second plant source, independent of tpvp's own generator, with organ labels.

Helios (Bailey, UC Davis; the Python package ``pyhelios3d``) grows a plant phytomer by phytomer with
its PlantArchitecture plugin and knows the organ of every triangle it makes. :func:`prepare_helios`
grows each species from a seed through the given ages (the first age builds the plant, every later
one advances the same plant's time, so the sessions are one plant growing), samples each session's
surface into a point cloud and writes the prepared layout of ``pheno4d prepare``
(:mod:`data_tools.prepared`), so ``tpvp experiments plants|season --dataset`` read it as they read
Pheno4D.

* Frame: metres, z up, the plant's base at the origin (Helios' own frame; drooping leaves may
  reach a few centimetres below z = 0).
* Surface: every triangle of the plant (a Helios leaf is a textured mesh whose transparent texels
  are not leaf), sampled uniformly by area, one point per ``spacing``² on average (a seeded numpy
  generator); points that fall on a transparent texel of a leaf texture are left out.
* Labels: organ codes (:data:`tpvp.scene.organs.ORGANS`; Helios' internodes are ``stem``); the
  manifest's ``label_kind`` says ``organ``.
* Dates: the plants are sown on :data:`SOWN`, a session ``age`` days later is dated that day (so
  ``<plant>_<MMDD>.ply`` names are valid and the sessions chain by date).
* Determinism: a plant's Helios seed comes from ``(seed, species, plant number)`` and each session's
  sampling seed from ``(seed, species, plant number, age)``; the same arguments give the same bytes.

pyhelios is optional: it is imported inside these functions only, and a Python without it (or with
a native library that fails to load) gets one line saying how to install it.
"""

from __future__ import annotations

import datetime as dt
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np
import pandas as pd

from data_tools.errors import ConfigError, DatasetError, PlantSimulatorError
from data_tools.manifest import stage_table
from data_tools.prepared import MANIFEST_COLUMNS, Scan, ScanConfig, session_pairs, write_scan
from tpvp.io import atomic_write_text
from tpvp.io.publish import staged_folder
from tpvp.scene.organs import CODE, ORGANS

__all__ = ["HELIOS_PACKAGE", "SOWN", "HeliosConfig", "Surface", "available_species", "check_ages",
           "grow", "helios_seed", "plant_name", "prepare_helios", "sample_surface"]

HELIOS_PACKAGE = "pyhelios3d==0.1.38"
INSTALL = (f"install it with `pip install {HELIOS_PACKAGE}` in this Python (or run `make test` or `make demo` "
           f"once: they install environment.txt, which lists it)")
SOWN = dt.date(2025, 1, 1)  # the day every plant is sown: a session `age` days later is dated then
#: Organ class -> PlantArchitecture's getter of every such triangle (Helios' internodes are stems).
ORGAN_GETTERS = {"stem": "getAllInternodeUUIDs", "leaf": "getAllLeafUUIDs", "petiole": "getAllPetioleUUIDs",
                 "peduncle": "getAllPeduncleUUIDs", "flower": "getAllFlowerUUIDs", "fruit": "getAllFruitUUIDs"}


@dataclass(frozen=True)
class HeliosConfig:
    """How the plants are grown and sampled."""

    spacing: float = 0.00125  # m: one point per spacing² of surface (a tomato at 30-39 days: ~115,000-225,000)
    plants: int = 1  # plants per species, each from its own seed
    seed: int = 0
    scan: ScanConfig = field(default_factory=ScanConfig)  # the normalised copies and ground truth

    def __post_init__(self):
        if not isinstance(self.spacing, (int, float)) or isinstance(self.spacing, bool) \
                or not np.isfinite(self.spacing) or self.spacing <= 0:
            raise ConfigError(f"spacing must be a positive number of metres, got {self.spacing!r}")
        for name, least in (("plants", 1), ("seed", 0)):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < least:
                raise ConfigError(f"{name} must be an integer of at least {least}, got {value!r}")
        if not isinstance(self.scan, ScanConfig):
            raise ConfigError(f"scan must be a ScanConfig, got {type(self.scan).__name__}")


@dataclass(frozen=True)
class Surface:
    """A plant's triangles as Helios made them, with their organs and leaf textures."""

    vertices: np.ndarray  # (T, 3, 3) metres
    organs: np.ndarray  # (T,) organ codes (tpvp.scene.organs.CODE)
    uv: np.ndarray  # (T, 3, 2) texture coordinates of the corners (zeros where untextured)
    texture: np.ndarray  # (T,) index into masks, -1: opaque
    masks: tuple = ()  # (H, W) bool: the texture's opaque texels, row 0 at the top (v = 1)


# --------------------------------------------------------------------------------------------
# Helios


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0].rstrip(" :") if text else type(exc).__name__


def _pyhelios():
    """The pyhelios package, or one line saying how to install it."""
    try:
        import pyhelios  # optional dependency: only this command needs it
    except ImportError as exc:
        raise PlantSimulatorError(f"Helios is not installed ({_first_line(exc)}): {INSTALL}") from None
    if getattr(pyhelios, "PlantArchitecture", None) is None:
        raise PlantSimulatorError(f"this pyhelios has no PlantArchitecture plugin: {INSTALL}")
    return pyhelios


def _open(pyhelios):
    """A new Helios Context and its PlantArchitecture, or one line saying Helios cannot load."""
    try:
        context = pyhelios.Context()
        return context, pyhelios.PlantArchitecture(context)
    except Exception as exc:  # pyhelios raises its own classes, RuntimeError or OSError when it cannot load
        raise PlantSimulatorError(f"Helios cannot load ({_first_line(exc)}): {INSTALL}") from None


def available_species() -> list[str]:
    """The plant models Helios' library offers (it says which, not tpvp); loads the native library."""
    context, plants = _open(_pyhelios())
    with context, plants:
        return sorted(plants.getAvailablePlantModels())


def helios_version() -> str:
    """The installed pyhelios3d's version (read without importing it)."""
    try:
        return version("pyhelios3d")
    except PackageNotFoundError:
        return "unknown"


def helios_seed(seed: int, species: str, plant: int) -> int:
    """Helios' random seed (32 bits) for plant number ``plant`` (1, 2, ...) of ``species``."""
    return int(np.random.SeedSequence([seed, zlib.crc32(species.encode()), plant]).generate_state(1)[0])


def _sampling_rng(seed: int, species: str, plant: int, age: int) -> np.random.Generator:
    return np.random.default_rng([seed, zlib.crc32(species.encode()), plant, age])


def plant_name(species: str, plant: int) -> str:
    """``tomato``, 1 -> ``Tomato01`` (the plant's folder and file names, as Pheno4D's)."""
    return f"{species[:1].upper()}{species[1:]}{plant:02d}"


def grow(species: str, ages, seed: int):
    """Grow one ``species`` plant from Helios seed ``seed``: built at ``ages[0]`` days, then the same
    plant advanced to each later age. Yields ``(age, Surface)`` per age."""
    pyhelios = _pyhelios()
    from pyhelios.types import vec3  # optional dependency, as above

    context, plants = _open(pyhelios)
    with context, plants:
        previous = None
        for age in ages:
            try:
                if previous is None:
                    context.seedRandomGenerator(int(seed))
                    plants.disableMessages()
                    plants.loadPlantModelFromLibrary(species)
                    plants.buildPlantInstanceFromLibrary(vec3(0.0, 0.0, 0.0), float(age))
                else:
                    plants.advanceTime(float(age - previous))
                surface = _surface(context, plants)
            except Exception as exc:  # pyhelios raises its own classes, RuntimeError or ValueError
                raise PlantSimulatorError(f"Helios failed to grow {species} (Helios seed {seed}) to {age} days: "
                                          f"{_first_line(exc)}") from None
            if len(surface.vertices) == 0:
                raise PlantSimulatorError(f"Helios grew no surface for {species} at {age} days")
            previous = age
            yield age, surface


def _fan(corners: np.ndarray):
    """Triangles of polygons with ``corners`` corners each (a fan from corner 0): the polygon of
    each triangle and its corners' positions in the polygon, (T, 3)."""
    count = np.maximum(corners - 2, 0)
    owner = np.repeat(np.arange(len(corners)), count)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count) + 1
    return owner, np.stack([np.zeros_like(k), k, k + 1], axis=1)


def _surface(context, plants) -> Surface:
    """Every primitive of the Context (triangles; patches fanned into two) with its organ and texture."""
    uuids = context.getAllUUIDs()
    organs = np.full(len(uuids), CODE["unknown"], dtype=np.int64)
    if not uuids:
        return Surface(np.zeros((0, 3, 3)), organs, np.zeros((0, 3, 2)), organs.copy())
    where = {uuid: i for i, uuid in enumerate(uuids)}
    for organ, getter in ORGAN_GETTERS.items():
        organs[[where[uuid] for uuid in getattr(plants, getter)()]] = CODE[organ]
    flat, offsets = context.getPrimitiveVertices(uuids)
    uv_flat, uv_offsets = context.getPrimitiveTextureUV(uuids)
    files = np.asarray(context.getPrimitiveTextureFile(uuids), dtype=object)
    corners = np.diff(np.asarray(offsets, dtype=np.int64)) // 3
    owner, local = _fan(corners)
    xyz = np.asarray(flat, dtype=np.float64).reshape(-1, 3)
    vertices = xyz[(np.asarray(offsets[:-1], dtype=np.int64) // 3)[owner][:, None] + local]

    uv_corners = np.diff(np.asarray(uv_offsets, dtype=np.int64)) // 2
    uv_xy = np.asarray(uv_flat, dtype=np.float64).reshape(-1, 2)
    textured = (files != "") & (uv_corners == corners)
    texture = np.full(len(uuids), -1, dtype=np.int64)
    masks = []
    for name in sorted(set(files[textured])):
        first = int(np.argmax(textured & (files == name)))
        mask = context.getPrimitiveTextureTransparencyData(uuids[first])
        if mask is not None:
            texture[textured & (files == name)] = len(masks)
            masks.append(np.asarray(mask, dtype=bool))
    uv = np.zeros((len(owner), 3, 2))
    has = textured[owner]
    uv[has] = uv_xy[(np.asarray(uv_offsets[:-1], dtype=np.int64) // 2)[owner][has][:, None] + local[has]]
    return Surface(vertices, organs[owner], uv, texture[owner], tuple(masks))


# --------------------------------------------------------------------------------------------
# sampling


def sample_surface(surface: Surface, spacing: float, rng: np.random.Generator):
    """Points uniform on the surface by area, one per ``spacing``² on average (a point on a
    transparent texel of a leaf texture is left out), and their organ codes."""
    v = surface.vertices
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    total = float(area.sum())
    n = int(round(total / spacing ** 2))
    triangle = np.searchsorted(np.cumsum(area), rng.random(n) * total, side="right").clip(max=len(area) - 1)
    root, r = np.sqrt(rng.random(n)), rng.random(n)
    weights = np.stack([1 - root, root * (1 - r), root * r], axis=1)
    points = np.einsum("ni,nij->nj", weights, v[triangle])
    keep = np.ones(n, dtype=bool)
    for index, mask in enumerate(surface.masks):
        on = surface.texture[triangle] == index
        keep[on] = _opaque(np.einsum("ni,nij->nj", weights[on], surface.uv[triangle[on]]), mask)
    return points[keep], surface.organs[triangle[keep]]


def _opaque(uv: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Whether each texture coordinate falls on an opaque texel (as Helios reads its masks: the
    nearest texel, row 0 at v = 1; its solid fractions agree within 0.3 %)."""
    height, width = mask.shape
    col = np.clip(np.rint(uv[:, 0] * (width - 1)).astype(np.int64), 0, width - 1)
    row = height - 1 - np.clip(np.rint(uv[:, 1] * (height - 1)).astype(np.int64), 0, height - 1)
    return mask[row, col]


# --------------------------------------------------------------------------------------------
# the dataset


def check_ages(ages) -> tuple[int, ...]:
    """Session ages in whole days: above 0, strictly increasing, within :data:`SOWN`'s year."""
    ages = list(ages)
    last = (dt.date(SOWN.year, 12, 31) - SOWN).days
    shown = " ".join(map(str, ages))
    if not ages or any(not isinstance(a, (int, np.integer)) or isinstance(a, bool) for a in ages):
        raise ConfigError(f"ages must be whole days, at least one, got {shown or 'none'}")
    if any(a <= 0 for a in ages) or any(b <= a for a, b in zip(ages, ages[1:])):
        raise ConfigError(f"ages must be positive days in strictly increasing order (each session after the "
                          f"previous one), got {shown}")
    if ages[-1] > last:
        raise ConfigError(f"ages must be at most {last} days (sessions are dated from the sowing day "
                          f"{SOWN.isoformat()} within its year), got {ages[-1]}")
    return tuple(int(a) for a in ages)


def _check_species(species, available: list[str]) -> tuple[str, ...]:
    species = list(species)
    if not species:
        raise ConfigError(f"give at least one species; Helios offers {', '.join(available)}")
    unknown = [s for s in species if s not in available]
    if unknown:
        raise ConfigError(f"unknown species {', '.join(map(repr, unknown))}; Helios {helios_version()} offers "
                          f"{', '.join(available)}")
    twice = sorted({s for s in species if species.count(s) > 1})
    if twice:
        raise ConfigError(f"species listed twice: {', '.join(twice)}")
    return tuple(species)


def prepare_helios(output, species, ages, config: HeliosConfig = HeliosConfig(), *, force: bool = False,
                   progress: bool = True) -> pd.DataFrame:
    """Grow ``config.plants`` plants of every ``species`` through ``ages`` (days; or a mapping
    species -> ages) and write them as a prepared dataset into ``output``
    (:mod:`data_tools.prepared`: per plant and session the plant in metres with organ labels, its
    normalised copy, its ground truth; ``manifest.csv``, ``pairs.csv``, ``NOTICE.md``), published whole
    (:func:`tpvp.io.publish.staged_folder`). Bad arguments and a Helios that cannot load are refused
    before anything is written; an existing dataset needs ``force``. Returns the manifest (its
    ``attrs["pairs"]``: the pairs)."""
    from tqdm.auto import tqdm

    if not isinstance(config, HeliosConfig):
        raise ConfigError(f"config must be a HeliosConfig, got {type(config).__name__}")
    species = list(species)
    if isinstance(ages, Mapping) and (missing := [s for s in species if s not in ages]):
        raise ConfigError(f"no ages given for {', '.join(missing)}")
    schedule = {s: check_ages(ages[s] if isinstance(ages, Mapping) else ages) for s in species}
    species = _check_species(species, available_species())
    output = Path(output)
    rows = []
    with staged_folder(output, what="dataset") as stage:
        if stage.existing("manifest.csv").exists() and not force:
            raise DatasetError(f"{output / 'manifest.csv'} exists: this dataset was grown already; pass --force "
                               f"to grow it again (files are replaced)")
        total = sum(len(a) for a in schedule.values()) * config.plants
        with tqdm(total=total, desc="grow Helios plants", unit="session", disable=not progress) as bar:
            for name in species:
                for number in range(1, config.plants + 1):
                    bar.set_postfix_str(f"{name} {number}/{config.plants}")
                    rows += _grow_plant(stage, name, number, schedule[name], config, bar)
        manifest = pd.DataFrame(rows, columns=list(MANIFEST_COLUMNS))
        pairs = session_pairs(manifest)
        _write_notice(stage, schedule, config)
        stage_table(stage, pairs, "pairs.csv")
        stage_table(stage, manifest, "manifest.csv")
    manifest.attrs["pairs"] = pairs
    return manifest


def _grow_plant(stage, species: str, number: int, ages, config: HeliosConfig, bar) -> list[dict]:
    seed = helios_seed(config.seed, species, number)
    rows = []
    for age, surface in grow(species, ages, seed):
        points, organs = sample_surface(surface, config.spacing, _sampling_rng(config.seed, species, number, age))
        scan = Scan(plant_name(species, number), species, SOWN + dt.timedelta(days=age), points, organs, "organ",
                    f"Helios (pyhelios3d {helios_version()}): {species}, Helios seed {seed}, {age} days")
        rows.append(write_scan(stage, scan, config.scan))
        bar.update()
    return rows


def _write_notice(stage, schedule: dict, config: HeliosConfig) -> None:
    codes = ", ".join(f"{code} {organ}" for code, organ in enumerate(ORGANS))
    text = [
        "# Helios-grown plants, made by tpvp",
        "",
        f"Grown with Helios' PlantArchitecture plugin (pyhelios3d {helios_version()}; "
        "https://github.com/PlantSimulationLab/PyHelios, licence MIT and LGPL-2.1-or-later; B. N. Bailey, "
        "\"Helios: A Scalable 3D Plant and Environmental Biophysical Modeling Framework\", Frontiers in Plant "
        "Science 10:1185, 2019) by `python -m data_tools helios`.",
        "",
        f"{config.plants} plant(s) per species, seed {config.seed}, sown on {SOWN.isoformat()}; each plant is "
        "built at its first age and advanced to the later ones (one plant growing).",
        "",
        *(f"- {name}: ages {', '.join(map(str, ages))} days" for name, ages in schedule.items()),
        "",
        f"Plants in metres, z up, base at the origin; the surface sampled uniformly by area, one point per "
        f"{1000 * config.spacing:g} mm squared on average (transparent leaf texels left out); labels are organ "
        f"codes ({codes}; manifest label_kind `organ`). Normalised copies scaled to a largest side of "
        f"{config.scan.largest_side} m and centred on the "
        f"{'bounding-box centre' if config.scan.centre == 'bbox' else 'centroid'}; ground-truth voxel grids at "
        f"{config.scan.gt_resolution} m.",
    ]
    atomic_write_text(stage.path("NOTICE.md"), "\n".join(text) + "\n")
