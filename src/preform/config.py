"""TOML configuration -> frozen dataclasses (docs/guide/configuration.md).

SI units inside; angles in the file are degrees and are converted here (``angular_speed`` is
stored in rad/s). Paths are resolved against the config file's folder.

The dataclasses below are the contract between the config and the rest of the package.
:func:`load_config` validates everything before any simulation starts and raises
:class:`preform.errors.ConfigError` naming the key, the value and what is expected.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .errors import ConfigError
from .machine import PATTERN_M, carrier_count_problem
from .materials import CONSTANTS as MATERIAL_CONSTANTS
from .materials import PRESETS as MATERIAL_PRESETS
from .materials import FibreMatrix, stiffness_problem
from .zone import SOLVERS as ZONE_SOLVERS
from .zone import ZONES


@dataclass(frozen=True)
class MandrelConfig:
    stl: Path                       # absolute path
    stl_unit: str = "m"             # "m" | "mm"
    centerline: str | Path = "auto"  # "auto" or absolute path of a CSV (x,y,z in the STL's unit, tip first)
    #: optional direction (STL frame) that the pose maps to machine +x at the tip; None: automatic
    roll_reference: tuple[float, float, float] | None = None
    #: which body of a multi-body STL is the mandrel: None (the STL must be one body), "largest"
    #: (by bounding-box diagonal), or an index into the bodies as the refusal lists them
    body: str | int | None = None


@dataclass(frozen=True)
class GuideRingConfig:
    radius: float                   # m
    offset: float = 0.0             # m, axial distance of the ring plane from the spool plane (towards +z)


@dataclass(frozen=True)
class MachineConfig:
    carriers: int                   # total; half warp, half weft
    spool_radius: float             # m
    #: rad/s (config file: deg/s); of a table, its first speed (what the set-up's expectations
    #: before the run, Ko's angle and H_inf at the start, are computed with)
    angular_speed: float
    pattern: str = "regular"        # "diamond" | "regular" | "hercules"
    guide_ring: GuideRingConfig | None = None
    axial_yarns: int = 0            # triaxial braiding: yarns laid along the mandrel ([axial_yarn])
    #: the yarn type of every carrier of a group: a pattern of type names repeated round each
    #: group from its first carrier (warp and weft alike); ("yarn",): [yarn] on every carrier
    carrier_yarns: tuple[str, ...] = ("yarn",)
    #: ``angular_speed`` given as a table over the braided length: ((braided_length_m, rad/s),
    #: ...), lengths increasing; empty: the speed is ``angular_speed`` throughout
    angular_speed_table: tuple[tuple[float, float], ...] = ()

    @property
    def angular_speeds(self) -> tuple[tuple[float, float], ...]:
        """The angular speed over the braided length, ((braided_length_m, rad/s), ...): the
        table, or the constant speed as one row (``stepping.setting_at`` reads either)."""
        return self.angular_speed_table or ((0.0, self.angular_speed),)

    @property
    def pattern_m(self) -> int:
        """Crossings over (and under) in a row: 1 diamond, 2 regular, 3 hercules."""
        return PATTERN_M[self.pattern]


@dataclass(frozen=True)
class YarnConfig:
    width: float                    # m
    thickness: float                # m
    tension: float = 4.7            # N, spool tension
    friction: float = 0.0           # yarn-yarn mu_y (Howell: at howell_reference_force)
    ring_friction: float = 0.0      # yarn-ring mu_r
    #: the yarn-yarn friction law at the crossings (docs/theory.md §4): "amontons" F^t <= mu N,
    #: or "howell" F^t <= a N^n with a = friction * howell_reference_force^(1 - n)
    friction_law: str = "amontons"
    #: Howell's index n (0 < n <= 1; 1 is Amontons); given with friction_law = "howell" only
    howell_index: float | None = None
    #: N, the normal force at which ``friction`` is Howell's coefficient: a fixed force, not one
    #: scaled with the spool tension (that would make the law homogeneous in the forces again,
    #: and the spool tension's effect vanish); 1 N makes ``friction`` Howell's a in N^(1-n)
    howell_reference_force: float = 1.0
    #: least width (m) a yarn narrows to where its neighbours leave it less room (paper §2.4.2);
    #: below it the yarns jam. None: half the width, the order a flat tow of spread filaments
    #: narrows to before they bunch into a round bundle
    min_width: float | None = None

    #: tow material data for the RTM hand-off (all three or none): linear density (g/km = tex),
    #: fibre density (kg/m^3), fibre radius (m)
    linear_density_tex: float | None = None
    fibre_density: float | None = None
    fibre_radius: float | None = None

    @property
    def has_material(self) -> bool:
        return self.linear_density_tex is not None

    @property
    def least_width(self) -> float:
        """``min_width``, or its default of half the width (m)."""
        return 0.5 * self.width if self.min_width is None else self.min_width


@dataclass(frozen=True)
class ProcessConfig:
    #: constant take-up speed (m/s) as a 1-tuple, or a table ((braided_length_m, speed_m_s), ...)
    take_up_speed: tuple[tuple[float, float], ...]
    initial_position: float         # m, mandrel tip to the supply plane at t = 0
    braid_length: float             # m of centerline to braid
    eccentricity: tuple[float, float] = (0.0, 0.0)   # m, machine x, y; of a table, its first row
    #: ``eccentricity`` given as a table over the braided length: ((braided_length_m, x_m, y_m),
    #: ...), lengths increasing; empty: ``eccentricity`` throughout
    eccentricity_table: tuple[tuple[float, float, float], ...] = ()
    #: a CSV of the mandrel's path (``preform.trajectory``; absolute path) that drives the run
    #: instead of ``take_up_speed``, ``eccentricity``, ``pose_lead`` and ``[machine]
    #: angular_speed`` (those then hold what the path gives, for the checks and estimates made
    #: before the run); None: the pose follows the centerline
    trajectory: Path | None = None
    #: axial distance (m) ahead of the supply plane where the pose puts the centerline on the axis
    #: (docs/architecture.md §2; see geometry/pose.py). None: "auto", chosen from the machine and the mandrel
    #: when the run is composed (``preform.reference.resolve_pose_lead``).
    pose_lead: float | None = None

    @property
    def eccentricities(self) -> tuple[tuple[float, float, float], ...]:
        """The eccentricity over the braided length, ((braided_length_m, x_m, y_m), ...)."""
        return self.eccentricity_table or ((0.0, *self.eccentricity),)

    @property
    def largest_eccentricity(self) -> float:
        """The largest distance (m) of the eccentricity from the machine axis over the run."""
        return max(math.hypot(x, y) for _, x, y in self.eccentricities)


@dataclass(frozen=True)
class ModelConfig:
    kind: str = "kinematic"         # "kinematic" | "interaction"
    time_step: float | None = None  # s; None: automatic step control
    start: str = "tip"              # "tip" | "random": initial fell points
    seed: int = 0                   # for start = "random"
    #: the interaction model's zone solver: "relax" (force-density relaxation,
    #: ``interaction/relax.py``: Newton's equations, ~10x faster at 144 carriers) | "newton"
    #: (the reference: damped Newton on the step's energy)
    solver: str = "relax"
    #: friction-bound updates per time step of the interaction model
    #: (``FrontalSettings.max_iterations``): 1 lags the bounds by one step; 3 brings H within
    #: ~0.1 % and the braid angle within ~0.15 deg of the time-step-converged run, at 1.6-2.5x
    #: the time (docs/decisions.md, "A time step's problem posed by its posed state")
    frontal_iterations: int = 1


#: convergence-zone snapshots a run writes where ``[output] snapshots`` is not given: the
#: interaction model's zone (crossings, friction, bridges) is what its snapshots are read for; the
#: kinematic zone is straight yarns from the carriers to the fell points, fully told by the
#: history, so it writes none unless asked
DEFAULT_SNAPSHOTS = {"interaction": 20, "kinematic": 0}


@dataclass(frozen=True)
class OutputConfig:
    dir: Path                       # absolute path
    field_edge_length: float | None = None   # m; None: a few yarn widths
    #: convergence-zone snapshots written; None: DEFAULT_SNAPSHOTS of the model (the interaction
    #: model's zone is worth looking at, the kinematic one's straight lines are not)
    snapshots: int | None = None

    def snapshot_count(self, kind: str) -> int:
        """The snapshots a run of ``[model] kind`` writes."""
        return DEFAULT_SNAPSHOTS.get(kind, 0) if self.snapshots is None else self.snapshots
    #: also write the fields on the mandrel's own (STL) triangles, surface_input.vtu
    #: (``fields.fields_on_input``, area-weighted), for a next tool that needs its mesh
    input_mesh_fields: bool = False
    #: draw the pictures (plots/*.png); false leaves the data files alone, for the many runs of
    #: a calibration or a large sweep, where the pictures would take most of each run's time
    pictures: bool = True


@dataclass(frozen=True)
class AxialYarnConfig:
    """The axial yarns of a triaxial braid; None fields take the [yarn] values."""

    width: float | None = None            # m
    thickness: float | None = None        # m
    linear_density_tex: float | None = None   # g/km


@dataclass(frozen=True)
class RtmConfig:
    """The RTM hand-off (preform.analysis.rtm): how fibre content and permeability are read."""

    #: m, the mould cavity the preform is compressed to; None: the preform's own thickness
    cavity_thickness: float | None = None
    permeability: str = "gebart"    # "gebart" | "kozeny_carman" | "table"
    packing: str = "hexagonal"      # Gebart's fibre packing: "hexagonal" | "quadratic"
    #: kozeny_carman: measured (K along, K across the fibres) in m^2 at fibre fraction vf_ref
    k_ref: tuple[float, float] | None = None
    vf_ref: float | None = None
    #: table: CSV of braid_angle_deg, fibre_volume_fraction, k1_m2, k2_m2 on a full grid
    table: Path | None = None


@dataclass(frozen=True)
class MaterialConfig:
    """``[material]``: the fibre and matrix of the yarns, for the structural hand-off
    (``preform.structural``): a named ``preset`` (``structural.materials.PRESETS``), any of whose
    constants the section's own keys replace, or all seven constants. One material for every
    yarn of the run, of every layer (yarn types of their own would each carry a table of these
    keys, laid over this one)."""

    constituents: FibreMatrix
    preset: str | None = None


@dataclass(frozen=True)
class LayerConfig:
    """One braided layer of ``[[layer]]`` (docs/guide/configuration.md): its direction of travel and its own
    values, laid over the run's top-level sections when the layer is braided
    (:meth:`Config.layer_config`), so that a change of a top-level section (``--model``, a
    sweep) reaches every layer that does not set that key itself. Validated at load against
    the top-level sections, like them."""

    #: "forward": braided from the centerline's tip, like a single layer; "backward": from its
    #: other end (the machine reverses), ``initial_position`` and ``braid_length`` from there
    direction: str = "forward"
    #: (section, field, value) of every key the layer sets, values as the section dataclasses
    #: hold them (SI, ``angular_speed`` in rad/s)
    overrides: tuple[tuple[str, str, object], ...] = ()

    def fields(self, section: str) -> dict:
        """The layer's own values of one section: field -> value."""
        return {name: value for sec, name, value in self.overrides if sec == section}


#: the name of the type ``[yarn]`` describes (the default of every carrier)
BASE_TYPE = "yarn"


@dataclass(frozen=True)
class YarnTypeConfig:
    """One ``[[yarn_type]]``: a named yarn whose keys are ``[yarn]``'s, each given one laid over
    ``[yarn]`` (:meth:`Config.yarn_type`), so a change of ``[yarn]`` (a sweep, a layer) reaches
    every key the type does not set itself."""

    name: str
    #: (field, value) of every [yarn] key the type sets, as YarnConfig holds them
    own: tuple[tuple[str, object], ...] = ()


@dataclass(frozen=True)
class FrictionPair:
    """One ``[[friction_pair]]``: the yarn-yarn friction where a yarn of type ``a`` crosses one
    of type ``b`` (a != b; a type with itself is that type's own ``friction``)."""

    a: str
    b: str
    friction: float


@dataclass(frozen=True)
class Config:
    mandrel: MandrelConfig
    machine: MachineConfig
    yarn: YarnConfig
    process: ProcessConfig
    model: ModelConfig = field(default_factory=ModelConfig)
    output: OutputConfig | None = None
    source: Path | None = None      # the TOML file this came from
    rtm: RtmConfig = field(default_factory=RtmConfig)
    axial_yarn: AxialYarnConfig = field(default_factory=AxialYarnConfig)
    #: ``[[layer]]`` tables, from the mandrel outwards; empty: one layer of the top-level sections
    layers: tuple[LayerConfig, ...] = ()
    #: ``[material]``, or None: no structural hand-off
    material: MaterialConfig | None = None
    #: ``[[yarn_type]]`` tables: named yarns besides ``[yarn]`` (the type named "yarn")
    yarn_types: tuple[YarnTypeConfig, ...] = ()
    #: ``[[friction_pair]]`` tables: the friction of crossings of two different types
    friction_pairs: tuple[FrictionPair, ...] = ()

    def layer_config(self, k: int) -> "Config":
        """The config that braids layer ``k`` (0-based): the top-level sections with the layer's
        own values laid over them; ``layers`` keeps the layers up to and including ``k``, so the
        echo (and a checkpoint's inputs hash) of a layer covers the layers it is braided on."""
        layer = self.layers[k]
        sections = {sec: dataclasses.replace(getattr(self, sec), **layer.fields(sec))
                    for sec in LAYER_SECTIONS}
        return dataclasses.replace(self, **sections, layers=self.layers[:k + 1])

    # -- yarn types (docs/guide/configuration.md, "Mixed yarns") ---------------------------------
    @property
    def type_names(self) -> tuple[str, ...]:
        """The yarn types, "yarn" ([yarn]) first, then the [[yarn_type]] tables in file order."""
        return (BASE_TYPE, *(t.name for t in self.yarn_types))

    def yarn_type(self, name: str) -> YarnConfig:
        """The yarn of type ``name``: [yarn] with the type's own keys laid over it."""
        if name == BASE_TYPE:
            return self.yarn
        for t in self.yarn_types:
            if t.name == name:
                return dataclasses.replace(self.yarn, **dict(t.own))
        raise KeyError(name)

    @property
    def types(self) -> tuple[YarnConfig, ...]:
        """Every type's yarn, in the order of :attr:`type_names`."""
        return tuple(self.yarn_type(name) for name in self.type_names)

    def carrier_types(self):
        """(2n,) int64: the type (index into :attr:`type_names`) of every yarn, warp 0 .. n-1
        then weft n .. 2n-1 (docs/architecture.md §2), the ``carrier_yarns`` pattern repeated
        round each group from its first carrier."""
        import numpy as np

        n = self.machine.carriers // 2
        index = {name: i for i, name in enumerate(self.type_names)}
        pattern = np.array([index[name] for name in self.machine.carrier_yarns], dtype=np.int64)
        per_group = pattern[np.arange(n) % len(pattern)]
        return np.concatenate([per_group, per_group])

    @property
    def is_mixed(self) -> bool:
        """True when some carrier carries a type other than [yarn]: the per-type models and
        fields are used; else the run is the uniform one, to the bit."""
        return any(name != BASE_TYPE for name in self.machine.carrier_yarns)

    def used_types(self) -> tuple[int, ...]:
        """The types (indices into :attr:`type_names`) some carrier carries, in type order."""
        names = set(self.machine.carrier_yarns)
        return tuple(i for i, name in enumerate(self.type_names) if name in names)

    def pair_friction(self):
        """((nt, nt) float64, (nt, nt) str): the yarn-yarn friction of every pair of types and
        where it comes from: "own" (a type with itself: its ``friction``), "pair" (a
        [[friction_pair]]), or "mean" (a pair not listed: the mean of the two types' own
        ``friction``, which lies between the two uniform braids; docs/decisions.md, "Mixed
        yarns")."""
        import numpy as np

        names = self.type_names
        own = np.array([t.friction for t in self.types], dtype=float)
        mu = 0.5 * (own[:, None] + own[None, :])
        source = np.full(mu.shape, "mean", dtype=object)
        np.fill_diagonal(mu, own)
        np.fill_diagonal(source, "own")
        for pair in self.friction_pairs:
            i, j = names.index(pair.a), names.index(pair.b)
            mu[i, j] = mu[j, i] = pair.friction
            source[i, j] = source[j, i] = "pair"
        return mu, source

    def axial(self) -> tuple[int, float, float, float | None]:
        """(count, width m, thickness m, tex or None) of the axial yarns."""
        a, y = self.axial_yarn, self.yarn
        return (self.machine.axial_yarns, a.width or y.width, a.thickness or y.thickness,
                a.linear_density_tex or y.linear_density_tex)


# --------------------------------------------------------------------------------------------
# Loading and validation
# --------------------------------------------------------------------------------------------

#: known keys per section, in the order of docs/guide/configuration.md
KEYS = {
    "mandrel": ("stl", "stl_unit", "centerline", "roll_reference", "body"),
    "machine": ("carriers", "spool_radius", "angular_speed", "pattern", "guide_ring", "axial_yarns",
                "carrier_yarns"),
    "yarn": ("width", "thickness", "tension", "friction", "ring_friction", "friction_law",
             "howell_index", "howell_reference_force", "min_width",
             "linear_density_tex", "fibre_density", "fibre_radius"),
    "process": ("take_up_speed", "initial_position", "eccentricity", "braid_length", "pose_lead",
                "trajectory"),
    "model": ("kind", "time_step", "start", "seed", "solver", "frontal_iterations"),
    "output": ("dir", "field_edge_length", "snapshots", "input_mesh_fields", "pictures"),
    "rtm": ("cavity_thickness", "permeability", "packing", "k_ref", "vf_ref", "table"),
    "axial_yarn": ("width", "thickness", "linear_density_tex"),
    "material": ("preset", *MATERIAL_CONSTANTS),
}
GUIDE_RING_KEYS = ("radius", "offset")
#: the dataclass fields a key sets where they are more than the key's own name (a table over
#: the braided length is kept beside the key's first value)
KEY_FIELDS = {("machine", "angular_speed"): ("angular_speed", "angular_speed_table"),
              ("process", "eccentricity"): ("eccentricity", "eccentricity_table")}
COMPANION_FIELDS = frozenset(name for names in KEY_FIELDS.values() for name in names[1:])
#: the arrays of tables besides [[layer]], and their keys
YARN_TYPE_KEYS = ("name", *KEYS["yarn"])
FRICTION_PAIR_KEYS = ("types", "friction")
ARRAYS_OF_TABLES = ("layer", "yarn_type", "friction_pair")
#: the sections a ``[[layer]]`` table may override, and its own keys
LAYER_SECTIONS = ("machine", "yarn", "process", "model", "axial_yarn")
LAYER_KEYS = ("direction",)
DIRECTIONS = ("forward", "backward")
REQUIRED_SECTIONS = ("mandrel", "machine", "yarn", "process")

STL_UNITS = ("m", "mm")
PATTERNS = tuple(PATTERN_M)  # "diamond", "regular", "hercules"
MODEL_KINDS = tuple(ZONES)  # "kinematic", "interaction"
STARTS = ("tip", "random")
SOLVERS = tuple(ZONE_SOLVERS)  # "newton", "relax"

#: coefficients of friction must lie in [0, MAX_FRICTION)
MAX_FRICTION = 2.0
#: ``[yarn] friction_law``: the yarn-yarn friction law at the crossings, and its keys (set in
#: [yarn] only: one law for the run, each pair's coefficient at its reference force)
FRICTION_LAWS = ("amontons", "howell")
FRICTION_LAW_KEYS = ("friction_law", "howell_index", "howell_reference_force")
#: ``[yarn] howell_reference_force`` (N) must lie in this range: crossing normal forces are
#: fractions of the spool tension, and a value outside is almost surely another unit
HOWELL_REFERENCE_RANGE = (1e-4, 1e3)
#: unit plausibility: above these the value was almost surely given in another unit
MAX_TAKE_UP_SPEED = 1.0         # m/s
MAX_ANGULAR_SPEED_DEG = 3600.0  # deg/s (10 revolutions per second)
MAX_MACHINE_RADIUS = 10.0       # m (spool and guide ring)
MAX_YARN_WIDTH = 0.1            # m
MAX_YARN_THICKNESS = 0.01       # m

_MISSING = object()


def load_config(path) -> Config:
    """Read and validate a TOML config (docs/guide/configuration.md); raises ConfigError naming the bad key.

    Relative paths in the file (STL, centerline CSV, output dir) resolve against the file's folder
    and are stored absolute. ``[output] dir`` defaults to ``results/<config stem>`` there.
    """
    path = Path(path).expanduser().resolve()
    if path.is_dir():
        raise ConfigError(f"config file {path} is a folder: give the path of a .toml case file "
                          "(e.g. examples/case_a.toml)")
    if not path.is_file():
        raise ConfigError(f"config file {path} not found")
    try:
        raw = path.read_bytes()
        # a UTF-8 byte-order mark (Notepad writes one) is not TOML; accept it
        text = raw.decode("utf-8-sig")
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not UTF-8 text (byte {err.start}: {raw[err.start:err.start + 1]!r}); "
                          "save the config as UTF-8") from None
    except OSError as err:
        raise ConfigError(f"{path}: cannot be read: {err.strerror or err}") from None
    return config_from_dict(data, base_dir=path.parent, name=path.stem, source=path)


def config_from_dict(data: dict, base_dir, name: str = "config", source=None) -> Config:
    """Validate a parsed TOML document (nested dicts) into a :class:`Config`.

    base_dir : folder that relative paths resolve against. name : stem of the default output dir.
    """
    base_dir = Path(base_dir).expanduser().resolve()
    layers_raw = data.get("layer", None)
    types_raw, pairs_raw = data.get("yarn_type", None), data.get("friction_pair", None)
    data = {k: v for k, v in data.items() if k not in ARRAYS_OF_TABLES}
    _check_layout(data)
    if layers_raw is not None and "trajectory" in data.get("process", {}):
        raise _Section("process", data).error(
            "trajectory", data["process"]["trajectory"], "a trajectory drives a run of one "
            "layer: leave it out of a config with [[layer]] tables")
    process, path = _process_and_path(_Section("process", data), base_dir)
    machine = _machine(_Section("machine", data), path)
    config = Config(
        mandrel=_mandrel(_Section("mandrel", data), base_dir),
        machine=machine,
        yarn=_yarn(_Section("yarn", data)),
        process=process,
        model=_model(_Section("model", data)),
        output=_output(_Section("output", data), base_dir, name),
        source=None if source is None else Path(source),
        rtm=_rtm(_Section("rtm", data), base_dir),
        axial_yarn=_axial_yarn(_Section("axial_yarn", data)),
        material=_structural_material(_Section("material", data)) if "material" in data else None,
    )
    if types_raw is not None or pairs_raw is not None or machine.carrier_yarns != ("yarn",):
        types = _yarn_types(types_raw, data)
        names = (BASE_TYPE, *(t.name for t in types))
        config = dataclasses.replace(config, yarn_types=types,
                                     friction_pairs=_friction_pairs(pairs_raw, names))
        _check_mix(config, "")
    if layers_raw is None:
        return config
    return dataclasses.replace(config, layers=_layers(layers_raw, data, config))


# ----- messages ------------------------------------------------------------------------------


def _fmt(value) -> str:
    """A value written as in TOML, for messages."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_fmt(v)}" for k, v in value.items()) + " }"
    return repr(value)


def _suggest(word: str, candidates) -> str:
    close = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.6)
    return f"did you mean {close[0]!r}? " if close else ""


def _home_of(key: str) -> str | None:
    """The section a key belongs to, if any."""
    return next((sec for sec, keys in KEYS.items() if key in keys), None)


def _check_layout(data: dict) -> None:
    """Unknown sections, top-level keys and unknown keys in every section, before any value."""
    for sec, table in data.items():
        if sec not in KEYS:
            _unknown_top_level(sec, table)
        if not isinstance(table, dict):
            raise ConfigError(f"[{sec}] must be a table (a [{sec}] section), got {sec} = {_fmt(table)}")
        for key in table:
            if key not in KEYS[sec]:
                _unknown_key(sec, key, table[key])
    for sec in REQUIRED_SECTIONS:
        if sec not in data:
            raise ConfigError(f"section [{sec}] is missing: expected keys {', '.join(KEYS[sec])}")


def _unknown_top_level(name, value) -> None:
    sections = ", ".join(f"[{s}]" for s in KEYS)
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        close = difflib.get_close_matches(name, ARRAYS_OF_TABLES, n=1, cutoff=0.6)
        hint = f"did you mean [[{close[0]}]]? " if close else ""
        raise ConfigError(f"unknown array of tables [[{name}]]: {hint}expected [[layer]] (one "
                          "table per braided layer), [[yarn_type]] (a named yarn) or "
                          "[[friction_pair]] (the friction of two yarn types)")
    if not isinstance(value, dict):
        home = _home_of(name)
        where = f"it belongs in [{home}]" if home else f"expected the sections {sections}"
        raise ConfigError(f"{name} = {_fmt(value)} is outside any section: {where}")
    hint = _suggest(name, KEYS)
    raise ConfigError(f"unknown section [{name}]: {hint}expected one of {sections}")


def _unknown_key(sec, key, value) -> None:
    hint = _suggest(key, KEYS[sec])
    home = _home_of(key)
    if not hint and home:
        hint = f"it belongs in [{home}]; "
    raise ConfigError(f"[{sec}] {key} = {_fmt(value)}: unknown key; {hint}"
                      f"expected one of {', '.join(KEYS[sec])}")


# ----- typed readers -------------------------------------------------------------------------


class _Section:
    """One table of the document with its name, for reading keys with error messages."""

    def __init__(self, name: str, data: dict, table: dict | None = None, prefix: str = ""):
        self.name = name
        self.table = data.get(name, {}) if table is None else table
        self.prefix = prefix   # "[[layer]] 2 " for a layer's sections

    def where(self, key: str) -> str:
        """How messages name the key: ``[name] key`` (a [[layer]] table's own keys: no name)."""
        return f"{self.prefix}[{self.name}] {key}" if self.name else f"{self.prefix}{key}"

    def error(self, key: str, value, expected: str) -> ConfigError:
        return ConfigError(f"{self.where(key)} = {_fmt(value)}: {expected}")

    def raw(self, key: str, default=_MISSING, expected: str = "a value"):
        if key in self.table:
            return self.table[key]
        if default is _MISSING:
            raise ConfigError(f"{self.where(key)} is missing: expected {expected}")
        return default

    def number(self, key, unit, default=_MISSING, minimum=None, positive=False) -> float | None:
        """A finite real; ``positive``: > 0; ``minimum``: >= minimum. ``unit`` for messages."""
        what = f"a {'positive ' if positive else ''}number ({unit})"
        if key not in self.table and default is not _MISSING:
            return default
        value = self.raw(key, expected=what)
        return _real(self, key, value, what, minimum=minimum, positive=positive)

    def integer(self, key, what, default=_MISSING, minimum=None) -> int:
        value = self.raw(key, default, what)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, value, f"expected {what}, not {_type_name(value)}")
        if minimum is not None and value < minimum:
            raise self.error(key, value, f"expected {what}")
        return value

    def choice(self, key, options, default=_MISSING) -> str:
        expected = "one of " + ", ".join(f'"{o}"' for o in options)
        value = self.raw(key, default, expected)
        if not isinstance(value, str):
            raise self.error(key, value, f"expected {expected}, not {_type_name(value)}")
        if value not in options:
            raise self.error(key, value, f"{_suggest(value, options)}expected {expected}")
        return value

    def vector(self, key, size, unit, default=_MISSING) -> tuple[float, ...] | None:
        what = f"a list of {size} numbers ({unit})"
        if key not in self.table and default is not _MISSING:
            return default
        value = self.raw(key, expected=what)
        if not isinstance(value, list) or len(value) != size:
            raise self.error(key, value, f"expected {what}")
        return tuple(_real(self, key, v, what, shown=value) for v in value)

    def path(self, key, base_dir: Path, what="a file path (relative to the config file)") -> Path:
        """An existing file; relative to ``base_dir``; returned absolute."""
        value = self.raw(key, expected=what)
        if not isinstance(value, str) or not value.strip():
            raise self.error(key, value, f"expected {what}, not {_type_name(value)}")
        resolved = _resolve(value, base_dir)
        if not resolved.is_file():
            state = "is a folder, not a file" if resolved.is_dir() else "file not found"
            raise self.error(key, value, f"{state}: {resolved}")
        return resolved


def _type_name(value) -> str:
    names = {bool: "a boolean", str: "a string", list: "a list", dict: "a table", int: "an integer",
             float: "a float"}
    return names.get(type(value), type(value).__name__)


def _real(sec: _Section, key, value, what, minimum=None, positive=False, shown=_MISSING) -> float:
    """Check one number read from ``sec.key``; ``shown`` is the value to print (whole list)."""
    shown = value if shown is _MISSING else shown
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise sec.error(key, shown, f"expected {what}, not {_type_name(value)}")
    if not math.isfinite(value):
        raise sec.error(key, shown, f"not finite: expected {what}")
    if positive and value <= 0:
        raise sec.error(key, shown, f"expected {what}: must be greater than zero")
    if minimum is not None and value < minimum:
        raise sec.error(key, shown, f"expected {what} >= {minimum:g}: must not be negative"
                        if minimum == 0 else f"expected {what} >= {minimum:g}")
    return float(value)


def _resolve(value: str, base_dir: Path) -> Path:
    p = Path(value).expanduser()
    return (p if p.is_absolute() else base_dir / p).resolve()


def _implausible(sec: _Section, key, value, limit, unit, hint) -> None:
    """Unit plausibility: a value above ``limit`` was almost surely given in another unit."""
    if value > limit:
        raise sec.error(key, sec.table[key],
                        f"expected {unit}; above {limit:g} {unit} is implausible ({hint})")


# ----- sections ------------------------------------------------------------------------------


def _mandrel(sec: _Section, base_dir: Path) -> MandrelConfig:
    stl = sec.path("stl", base_dir)
    unit = sec.choice("stl_unit", STL_UNITS, default="m")
    centerline = sec.raw("centerline", "auto")
    if centerline != "auto":
        centerline = sec.path("centerline", base_dir, '"auto" or the path of a CSV of x,y,z points')
    roll = sec.vector("roll_reference", 3, "a direction in the STL frame", default=None)
    if roll is not None and not any(roll):
        raise sec.error("roll_reference", list(roll), "expected a non-zero direction [x, y, z]")
    return MandrelConfig(stl=stl, stl_unit=unit, centerline=centerline, roll_reference=roll,
                         body=_body(sec))


def _body(sec: _Section) -> str | int | None:
    """``[mandrel] body``: "largest" or a non-negative index; absent: None."""
    if "body" not in sec.table:
        return None
    value = sec.table["body"]
    if value == "largest":
        return "largest"
    if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
        return value
    raise sec.error("body", value, 'expected "largest" or the index (0, 1, ...) of a body in the '
                    "list the mandrel check prints")


def _machine(sec: _Section, trajectory=None) -> MachineConfig:
    pattern = sec.choice("pattern", PATTERNS, default="regular")
    carriers = sec.integer("carriers", "an even integer number of carriers (warp + weft)")
    problem = carrier_count_problem(carriers, pattern)
    if problem:
        raise sec.error("carriers", carriers, problem)
    spool = sec.number("spool_radius", "m", positive=True)
    _implausible(sec, "spool_radius", spool, MAX_MACHINE_RADIUS, "m", "mm? divide by 1000")
    speed, table = _angular_speed(sec, trajectory)
    ring = _guide_ring(sec, spool)
    axial = sec.integer("axial_yarns", "a non-negative integer number of axial yarns", default=0, minimum=0)
    return MachineConfig(carriers=carriers, spool_radius=spool, angular_speed=speed,
                         pattern=pattern, guide_ring=ring, axial_yarns=axial,
                         angular_speed_table=table, carrier_yarns=_carrier_yarns(sec))


def _angular_speed(sec: _Section, trajectory=None) -> tuple[float, tuple[tuple[float, float], ...]]:
    """``[machine] angular_speed``: a number (deg/s) or a table [[braided_length_m, deg/s], ...]
    as ``take_up_speed`` is; -> (the first speed, the table or ()) in rad/s. With a trajectory
    (``preform.trajectory.Trajectory``) the path's angular speeds, and the key is refused."""
    if trajectory is not None:
        _refused_with_path(sec, "angular_speed", trajectory)
        table = trajectory.angular_speed_table()
        return table[0][1], (table if len(table) > 1 else ())
    what = "a positive number (deg/s) or a table [[braided_length_m, speed_deg_s], ...]"
    value = sec.raw("angular_speed", expected=what)
    if isinstance(value, list):
        table = _speed_table(sec, value, what, key="angular_speed")
    else:
        table = ((0.0, _real(sec, "angular_speed", value, what, positive=True)),)
    for _, speed in table:
        _implausible(sec, "angular_speed", speed, MAX_ANGULAR_SPEED_DEG, "deg/s",
                     "10 revolutions per second; the carrier speed about the machine axis is in "
                     "deg/s, 1 rpm = 6 deg/s")
    radians = tuple((length, math.radians(speed)) for length, speed in table)
    return radians[0][1], (radians if len(radians) > 1 else ())


def _refused_with_path(sec: _Section, key: str, trajectory) -> None:
    """A key the trajectory replaces, given anyway: an error naming both."""
    if key in sec.table:
        raise sec.error(key, sec.table[key], f"not with [process] trajectory = "
                        f"{_fmt(trajectory.name)}: the path gives the mandrel's pose and the "
                        "speeds; leave this key out")


def _carrier_yarns(sec: _Section) -> tuple[str, ...]:
    """``carrier_yarns``: one type name (every carrier) or a non-empty list of names (a pattern
    round each group); the names are checked against the types in :func:`_check_mix`."""
    what = ('a yarn type name ("yarn" or a [[yarn_type]] name) or a list of them, repeated '
            "round each group from its first carrier")
    value = sec.raw("carrier_yarns", BASE_TYPE, what)
    names = [value] if isinstance(value, str) else value
    if not isinstance(names, list) or not names or not all(isinstance(v, str) for v in names):
        raise sec.error("carrier_yarns", value, f"expected {what}")
    return tuple(names)


def _guide_ring(machine: _Section, spool_radius: float) -> GuideRingConfig | None:
    table = machine.raw("guide_ring", None)
    if table is None:
        return None
    if not isinstance(table, dict):
        raise machine.error("guide_ring", table, "expected a table { radius = ..., offset = ... } (m)")
    sec = _Section("machine", {}, table={f"guide_ring.{k}": v for k, v in table.items()},
                   prefix=machine.prefix)
    for key in table:
        if key not in GUIDE_RING_KEYS:
            hint = _suggest(key, GUIDE_RING_KEYS)
            raise sec.error(f"guide_ring.{key}", table[key],
                            f"unknown key; {hint}expected one of {', '.join(GUIDE_RING_KEYS)}")
    radius = sec.number("guide_ring.radius", "m", positive=True)
    offset = sec.number("guide_ring.offset", "m, axial distance from the spool plane", default=0.0,
                        minimum=0.0)
    if radius >= spool_radius:
        raise sec.error("guide_ring.radius", radius,
                        f"expected less than [machine] spool_radius = {_fmt(spool_radius)} (m)")
    return GuideRingConfig(radius=radius, offset=offset)


def _yarn(sec: _Section) -> YarnConfig:
    width = sec.number("width", "m", positive=True)
    _implausible(sec, "width", width, MAX_YARN_WIDTH, "m", "mm? divide by 1000")
    thickness = sec.number("thickness", "m", positive=True)
    _implausible(sec, "thickness", thickness, MAX_YARN_THICKNESS, "m", "mm? divide by 1000")
    tension = sec.number("tension", "N", default=YarnConfig.tension, positive=True)
    frictions = {key: _friction(sec, key) for key in ("friction", "ring_friction")}
    frictions.update(_friction_law(sec))
    min_width = sec.number("min_width", "m", default=None, positive=True)
    if min_width is not None and min_width > width:
        raise sec.error("min_width", min_width, f"expected at most {sec.where('width')} = {_fmt(width)} "
                        "(m): the least width a yarn narrows to")
    material = _material(sec)
    return YarnConfig(width=width, thickness=thickness, tension=tension, min_width=min_width,
                      **frictions, **material)


#: a yarn type's name: a letter, then letters, digits and "_" (it names fields, coverage_<type>)
RESERVED_TYPE_NAMES = ("warp", "weft", "axial")
TYPE_NAME_CHARS = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_"


def _array_of_tables(raw, name: str, once: str, each: str = "", non_empty: bool = False) -> None:
    """A ``[[name]]`` array of tables as TOML reads it (a list of dicts; ``non_empty``: at least
    one), else an error naming what was written instead: "[name]" (one bracket) or a value."""
    if isinstance(raw, dict):
        raise ConfigError(f"[{name}] must be an array of tables: write [[{name}]] (two brackets) "
                          f"once per {once}")
    if not isinstance(raw, list) or (non_empty and not raw) or not all(isinstance(t, dict) for t in raw):
        raise ConfigError(f"{name} = {_fmt(raw)}: expected [[{name}]] tables{each}")


def _yarn_types(raw, data: dict) -> tuple[YarnTypeConfig, ...]:
    """``[[yarn_type]]`` tables -> YarnTypeConfigs: each is [yarn] with its keys laid over it,
    read by the [yarn] reader, so a bad value names its type (``[[yarn_type]] "polyester"
    width = ...``)."""
    if raw is None:
        return ()
    _array_of_tables(raw, "yarn_type", "named yarn", ", one per named yarn")
    types, seen = [], {BASE_TYPE: "[yarn]"}
    for k, table in enumerate(raw, start=1):
        prefix = f"[[yarn_type]] {k} "
        name = table.get("name", None)
        if name is None:
            raise ConfigError(f'{prefix}has no name: give name = "..." (the name carrier_yarns '
                              "and [[friction_pair]] use)")
        if (not isinstance(name, str) or not name or not name[0].isalpha()
                or any(ch not in TYPE_NAME_CHARS for ch in name)):
            raise ConfigError(f"{prefix}name = {_fmt(name)}: expected a name of letters, digits "
                              'and "_", starting with a letter (it names fields: coverage_<name>)')
        if name in RESERVED_TYPE_NAMES:
            raise ConfigError(f'{prefix}name = "{name}": reserved (the fields of the groups and the '
                              f"axial yarns are named {', '.join(RESERVED_TYPE_NAMES)}); choose another")
        if name in seen:
            again = ("the type [yarn] describes; give its keys in [yarn]" if name == BASE_TYPE
                     else f"a type named twice (also {seen[name]})")
            raise ConfigError(f'{prefix}name = "{name}": {again}')
        seen[name] = f"[[yarn_type]] {k}"
        prefix = f'[[yarn_type]] "{name}" '
        for key in table:
            if key not in YARN_TYPE_KEYS:
                hint = _suggest(key, YARN_TYPE_KEYS)
                raise ConfigError(f"{prefix}{key} = {_fmt(table[key])}: unknown key; {hint}"
                                  f"expected name or a [yarn] key ({', '.join(KEYS['yarn'])})")
        for key in FRICTION_LAW_KEYS:
            if key in table:
                raise ConfigError(f"{prefix}{key} = {_fmt(table[key])}: the crossings' friction "
                                  "law is the run's: set it once in [yarn] (a type's friction, "
                                  "and [[friction_pair]]'s, are its coefficient at "
                                  "howell_reference_force)")
        own = {key: v for key, v in table.items() if key != "name"}
        merged = {**data.get("yarn", {}), **own}
        if any(key in own for key in MATERIAL):   # its tow data go together, not with [yarn]'s
            merged = {**{k: v for k, v in merged.items() if k not in MATERIAL},
                      **{k: v for k, v in own.items() if k in MATERIAL}}
        yarn = _yarn(_Section("", {}, table=merged, prefix=prefix))
        types.append(YarnTypeConfig(name=name, own=tuple((key, getattr(yarn, key)) for key in own)))
    return tuple(types)


def _friction_pairs(raw, names) -> tuple[FrictionPair, ...]:
    """``[[friction_pair]]`` tables: ``types = [a, b]`` of two different known types and their
    ``friction``; a pair listed twice (in either order) is an error."""
    if raw is None:
        return ()
    _array_of_tables(raw, "friction_pair", "pair of yarn types")
    known = ", ".join(f'"{n}"' for n in names)
    pairs, seen = [], {}
    for k, table in enumerate(raw, start=1):
        sec = _Section("", {}, table=table, prefix=f"[[friction_pair]] {k} ")
        for key in table:
            if key not in FRICTION_PAIR_KEYS:
                hint = _suggest(key, FRICTION_PAIR_KEYS)
                raise sec.error(key, table[key], f"unknown key; {hint}expected types, friction")
        what = f'two yarn type names, e.g. ["yarn", "polyester"] (the types: {known})'
        types = sec.raw("types", expected=what)
        if (not isinstance(types, list) or len(types) != 2
                or not all(isinstance(t, str) for t in types)):
            raise sec.error("types", types, f"expected {what}")
        for t in types:
            if t not in names:
                raise sec.error("types", types, f'unknown yarn type "{t}": {_suggest(t, names)}'
                                f"expected one of {known}")
        a, b = types
        if a == b:
            raise sec.error("types", types, f'a type with itself: its friction is the type\'s own '
                            f'friction ({"[yarn]" if a == BASE_TYPE else f"[[yarn_type]] {_fmt(a)}"}'
                            " friction); expected two different types")
        key = frozenset(types)
        if key in seen:
            raise sec.error("types", types, f"the pair is listed twice (also [[friction_pair]] "
                            f"{seen[key]}); give each pair of types once")
        seen[key] = k
        pairs.append(FrictionPair(a=a, b=b, friction=_friction(sec, "friction", required=True)))
    return tuple(pairs)


def _check_mix(config: Config, prefix: str) -> None:
    """The carriers' types against the types, the pattern against the group, the tow data of
    the types on the carriers against each other (prefix: "[[layer]] k " for a layer)."""
    ma = config.machine
    names = config.type_names
    value = list(ma.carrier_yarns) if len(ma.carrier_yarns) > 1 else ma.carrier_yarns[0]
    where = f"{prefix}[machine] carrier_yarns = {_fmt(value)}"
    for name in ma.carrier_yarns:
        if name not in names:
            known = ", ".join(f'"{n}"' for n in names)
            raise ConfigError(f'{where}: unknown yarn type "{name}": {_suggest(name, names)}'
                              f"expected one of {known} ([yarn], or a [[yarn_type]] name)")
    n = ma.carriers // 2
    if n % len(ma.carrier_yarns):
        raise ConfigError(f"{where}: a pattern of {len(ma.carrier_yarns)} does not divide the "
                          f"{n} carriers of a group ([machine] carriers = {ma.carriers}): expected a "
                          "pattern whose length divides carriers / 2, repeated round each group")
    used = [config.types[i] for i in config.used_types()]
    with_tow = [t.has_material for t in used]
    if any(with_tow) and not all(with_tow):
        lacking = [config.type_names[i] for i in config.used_types()
                   if not config.yarn_type(config.type_names[i]).has_material]
        raise ConfigError(f"{where}: the yarn type {_fmt(lacking[0])} has no tow material data "
                          "(linear_density_tex, fibre_density, fibre_radius) while other types on "
                          "the carriers have: give them for every type on the carriers")


def mix_lines(config: Config) -> list[str]:
    """What ``preform check`` says of a mix: the carriers of every type per group and the
    friction of every pair of the types on the carriers, with where it comes from; [] for a
    uniform config without yarn types."""
    if not config.is_mixed and not config.yarn_types and not config.friction_pairs:
        return []
    names = config.type_names
    kinds = config.carrier_types()
    n = config.machine.carriers // 2
    used = config.used_types()
    per = ", ".join(f"{names[i]} {int((kinds[:n] == i).sum())}" for i in used)
    lines = [f"yarns: {per} carriers per group (warp and weft alike; carrier_yarns "
             f"{_fmt(list(config.machine.carrier_yarns))} from each group's first carrier)"]
    mu, source = config.pair_friction()
    words = {"own": "the type's own friction", "pair": "[[friction_pair]]",
             "mean": "not listed: the mean of the two types' own friction"}
    for a in used:
        for b in used:
            if b >= a:
                lines.append(f"friction {names[a]}-{names[b]}: {mu[a, b]:g} ({words[source[a, b]]})")
    unused = [n_ for i, n_ in enumerate(names) if i not in used]
    if unused:
        lines.append(f"yarn types on no carrier: {', '.join(unused)}")
    shapes = {(config.types[i].width, config.types[i].thickness) for i in used}
    if config.model.kind == "interaction" and len(shapes) > 1:
        lines.append("the interaction model's crossings take [yarn]'s width and thickness for "
                     "every type (each type's own in the fields and the kinematic deposition)")
    return lines


#: material keys of [yarn] (given together) and their plausible ranges with a unit hint
MATERIAL = {
    "linear_density_tex": ("g/km (tex)", 1.0, 1e5, "a 12K carbon tow is 800 tex"),
    "fibre_density": ("kg/m^3", 500.0, 5000.0, "carbon 1760-1800, glass 2550-2600 kg/m^3; g/cm^3? multiply by 1000"),
    "fibre_radius": ("m", 5e-7, 1e-4, "carbon 3.5e-6 m; um? multiply by 1e-6"),
}


def _material(sec: _Section) -> dict:
    given = [k for k in MATERIAL if k in sec.table]
    if given and len(given) < len(MATERIAL):
        missing = [k for k in MATERIAL if k not in sec.table]
        raise sec.error(given[0], sec.table[given[0]],
                        f"the RTM material data go together: give {', '.join(missing)} too")
    out = {}
    for key, (unit, lo, hi, hint) in MATERIAL.items():
        if key not in sec.table:
            continue
        value = sec.number(key, unit, positive=True)
        if not lo <= value <= hi:
            raise sec.error(key, value, f"expected {lo:g} to {hi:g} {unit} ({hint})")
        out[key] = value
    return out


#: [material] constants: (unit, plausible range, hint for a value in another unit)
MODULUS_RANGE = (1e8, 2e12)
STRUCTURAL_UNITS = {name: ("Pa", MODULUS_RANGE, "GPa? multiply by 1e9") for name in MATERIAL_CONSTANTS
                    if not name.endswith(("nu12", "nu"))}


def _structural_material(sec: _Section) -> MaterialConfig:
    """``[material]``: a preset and/or the seven constants (Pa, Poisson's ratios), validated."""
    preset = None
    values = {}
    if "preset" in sec.table:
        preset = sec.choice("preset", tuple(MATERIAL_PRESETS))
        base = MATERIAL_PRESETS[preset][0]
        values = {name: getattr(base, name) for name in MATERIAL_CONSTANTS}
    missing = [name for name in MATERIAL_CONSTANTS if name not in sec.table and name not in values]
    if missing:
        raise ConfigError(f"[material] {', '.join(missing)} missing: give preset = one of "
                          f"{', '.join(json.dumps(p) for p in MATERIAL_PRESETS)}, or all of "
                          f"{', '.join(MATERIAL_CONSTANTS)} (Pa)")
    for name in MATERIAL_CONSTANTS:
        if name not in sec.table:
            continue
        if name in STRUCTURAL_UNITS:
            unit, (lo, hi), hint = STRUCTURAL_UNITS[name]
            value = sec.number(name, unit, positive=True)
            if not lo <= value <= hi:
                raise sec.error(name, sec.table[name], f"expected {lo:g} to {hi:g} Pa ({hint})")
        else:
            value = sec.number(name, "Poisson's ratio")
            if not -1.0 < value < 0.5:
                raise sec.error(name, value, "expected a Poisson's ratio between -1 and 0.5")
        values[name] = value
    constituents = FibreMatrix(**values)
    key, why = stiffness_problem(constituents)
    if key:
        raise ConfigError(f"[material] {key} = {_fmt(values[key])}: {why}")
    return MaterialConfig(constituents=constituents, preset=preset)


def _axial_yarn(sec: _Section) -> AxialYarnConfig:
    return AxialYarnConfig(width=sec.number("width", "m", default=None, positive=True),
                           thickness=sec.number("thickness", "m", default=None, positive=True),
                           linear_density_tex=sec.number("linear_density_tex", "g/km (tex)", default=None,
                                                         positive=True))


def _layers(raw, data: dict, config: Config) -> tuple[LayerConfig, ...]:
    """``[[layer]]`` tables -> LayerConfigs: each layer's sections are the top-level ones with the
    layer's keys laid over them (a layer's ``guide_ring`` replaces the top-level one), read by
    the same readers, so a bad value names its layer (``[[layer]] 2 [yarn] thickness = ...``)."""
    _array_of_tables(raw, "layer", "braided layer, from the mandrel outwards",
                     ", one per braided layer", non_empty=True)
    layers = [_layer(k, table, data) for k, table in enumerate(raw, start=1)]
    whole = dataclasses.replace(config, layers=tuple(layers))
    if config.yarn_types or config.friction_pairs or any(
            whole.layer_config(k).is_mixed for k in range(len(layers))):
        for k in range(len(layers)):
            _check_mix(whole.layer_config(k), f"[[layer]] {k + 1} ")
    with_tow = [whole.layer_config(k).yarn.has_material for k in range(len(layers))]
    if any(with_tow) and not all(with_tow):
        k = with_tow.index(False) + 1
        raise ConfigError(f"[[layer]] {k} [yarn] has no tow material data (linear_density_tex, "
                          "fibre_density, fibre_radius) while other layers have: give them for "
                          "every layer (or at the top level in [yarn]) for the stacked RTM fields")
    return tuple(layers)


def _layer(k: int, table: dict, data: dict) -> LayerConfig:
    prefix = f"[[layer]] {k} "
    expected = ", ".join([*LAYER_KEYS, *(f"[layer.{s}]" for s in LAYER_SECTIONS)])
    for key, value in table.items():
        if key in LAYER_KEYS:
            continue
        if key not in LAYER_SECTIONS:
            whole = " (it is set once for all layers, at the top level)" if key in KEYS else ""
            hint = _suggest(key, [*LAYER_KEYS, *LAYER_SECTIONS])
            raise ConfigError(f"{prefix}{key} = {_fmt(value)}: unknown key{whole}; {hint}expected "
                              f"one of {expected}")
        if not isinstance(value, dict):
            raise ConfigError(f"{prefix}{key} = {_fmt(value)}: expected a table [layer.{key}] of "
                              f"[{key}] keys for this layer")
        for sub in value:
            if sub not in KEYS[key]:
                hint = _suggest(sub, KEYS[key])
                raise ConfigError(f"{prefix}[{key}] {sub} = {_fmt(value[sub])}: unknown key; "
                                  f"{hint}expected one of {', '.join(KEYS[key])}")
    merged = {sec: {**data.get(sec, {}), **table.get(sec, {})} for sec in LAYER_SECTIONS}
    direction = _Section("", {}, table=table, prefix=prefix).choice("direction", DIRECTIONS,
                                                                     default="forward")
    readers = {"machine": _machine, "yarn": _yarn, "process": _process, "model": _model,
               "axial_yarn": _axial_yarn}
    overrides = []
    for sec, read in readers.items():   # the merged section validated; the layer's keys kept
        section = read(_Section(sec, merged, prefix=prefix))
        overrides += [(sec, name, getattr(section, name)) for key in table.get(sec, {})
                      for name in KEY_FIELDS.get((sec, key), (key,))]
    return LayerConfig(direction=direction, overrides=tuple(overrides))


RTM_MODELS = ("gebart", "kozeny_carman", "table")
PACKINGS = ("hexagonal", "quadratic")


def _rtm(sec: _Section, base_dir: Path) -> RtmConfig:
    model = sec.choice("permeability", RTM_MODELS, default="gebart")
    k_ref = sec.vector("k_ref", 2, "m^2, along and across the fibres", default=None)
    vf_ref = sec.number("vf_ref", "fibre volume fraction", default=None, positive=True)
    if model == "kozeny_carman" and (k_ref is None or vf_ref is None):
        raise sec.error("permeability", model, "needs k_ref = [K_along, K_across] (m^2) and vf_ref")
    if k_ref is not None and min(k_ref) <= 0:
        raise sec.error("k_ref", list(k_ref), "expected two positive permeabilities (m^2)")
    if vf_ref is not None and vf_ref >= 1:
        raise sec.error("vf_ref", vf_ref, "expected a fibre volume fraction below 1")
    table = sec.path("table", base_dir, "the path of a CSV") if "table" in sec.table else None
    if model == "table" and table is None:
        raise sec.error("permeability", model, 'needs table = "K1_K2.csv" (braid_angle_deg, '
                        "fibre_volume_fraction, k1_m2, k2_m2)")
    return RtmConfig(cavity_thickness=sec.number("cavity_thickness", "m", default=None, positive=True),
                     permeability=model, packing=sec.choice("packing", PACKINGS, default="hexagonal"),
                     k_ref=k_ref, vf_ref=vf_ref, table=table)


def _friction(sec: _Section, key: str, required: bool = False) -> float:
    """A coefficient of friction in [0, MAX_FRICTION); absent: YarnConfig's default, or an error
    where ``required``."""
    expected = f"expected a coefficient of friction in [0, {MAX_FRICTION:g})"
    default = _MISSING if required else getattr(YarnConfig, key)
    mu = sec.number(key, "coefficient of friction", default=default)
    if mu < 0:
        raise sec.error(key, sec.table[key], f"must not be negative; {expected}")
    if mu >= MAX_FRICTION:
        raise sec.error(key, sec.table[key], expected)
    return mu


def _friction_law(sec: _Section) -> dict:
    """``friction_law``, ``howell_index`` and ``howell_reference_force`` of [yarn]: Howell's keys
    only with ``friction_law = "howell"``, which needs the index."""
    law = sec.choice("friction_law", FRICTION_LAWS, default=YarnConfig.friction_law)
    if law != "howell":
        for key in ("howell_index", "howell_reference_force"):
            if key in sec.table:
                raise sec.error(key, sec.table[key], f'applies to friction_law = "howell" only '
                                f'(friction_law is "{law}"); set friction_law = "howell" or '
                                "remove it")
        return {"friction_law": law}
    what = "Howell's index n, 0 < n <= 1 (1 is Amontons; fibre tows 0.7-0.95, docs/theory.md)"
    if "howell_index" not in sec.table:
        raise sec.error("friction_law", law, f"needs howell_index = n: {what}")
    n = sec.number("howell_index", what)
    if not 0.0 < n <= 1.0:
        raise sec.error("howell_index", sec.table["howell_index"], f"expected {what}")
    lo, hi = HOWELL_REFERENCE_RANGE
    ref = sec.number("howell_reference_force", "N, the normal force at which friction is "
                     "Howell's coefficient", default=YarnConfig.howell_reference_force,
                     positive=True)
    if not lo <= ref <= hi:
        raise sec.error("howell_reference_force", sec.table["howell_reference_force"],
                        f"expected a normal force between {lo:g} and {hi:g} N (crossing normal "
                        "forces are fractions of the spool tension)")
    return {"friction_law": law, "howell_index": n, "howell_reference_force": ref}


def _process(sec: _Section) -> ProcessConfig:
    """``[process]`` of a [[layer]] table (no trajectory there)."""
    return _process_and_path(sec, None)[0]


def _process_and_path(sec: _Section, base_dir: Path | None):
    """``[process]`` -> (ProcessConfig, the trajectory read from its CSV or None)."""
    path = _trajectory(sec, base_dir)
    if path is not None:
        return _process_of_path(sec, path), path
    position, table = _eccentricity(sec)
    return ProcessConfig(
        take_up_speed=_take_up_speed(sec),
        initial_position=sec.number("initial_position", "m, mandrel tip beyond the supply plane",
                                    minimum=0.0),
        braid_length=sec.number("braid_length", "m of centerline", positive=True),
        eccentricity=position,
        eccentricity_table=table,
        pose_lead=_pose_lead(sec),
    ), None


def _trajectory(sec: _Section, base_dir: Path | None):
    """``[process] trajectory``: the path's CSV read and checked
    (``preform.trajectory.read_trajectory``), or None when the key is absent."""
    if "trajectory" not in sec.table:
        return None
    if base_dir is None or sec.prefix:
        raise sec.error("trajectory", sec.table["trajectory"], "a trajectory drives a run of "
                        "one layer: give it at the top level of a config without [[layer]] tables")
    from .trajectory import read_trajectory

    path = sec.path("trajectory", base_dir, "the path of a CSV of the mandrel's path (the "
                    "columns of process.csv), relative to the config file")
    return read_trajectory(path, max_take_up_speed=MAX_TAKE_UP_SPEED,
                           max_angular_speed_deg=MAX_ANGULAR_SPEED_DEG)


def _process_of_path(sec: _Section, path) -> ProcessConfig:
    """The process of a run driven by a trajectory: ``take_up_speed`` the path's over its braided
    length, the first pose's eccentricity and tip position resolved with the mandrel
    (``reference.resolve_pose_lead``); the keys the path replaces are refused."""
    for key in ("take_up_speed", "initial_position", "eccentricity", "pose_lead"):
        _refused_with_path(sec, key, path)
    return ProcessConfig(take_up_speed=path.take_up_speed_table(), initial_position=0.0,
                         braid_length=sec.number("braid_length", "m of centerline", positive=True),
                         pose_lead=0.0, trajectory=path.path)


def _eccentricity(sec: _Section) -> tuple[tuple[float, float], tuple[tuple[float, float, float], ...]]:
    """``[process] eccentricity``: [x, y] (m), or a table [[braided_length_m, x_m, y_m], ...]
    with increasing lengths; -> (the first position, the table or ())."""
    value = sec.table.get("eccentricity")
    if isinstance(value, list) and value and all(isinstance(row, list) for row in value):
        what = "a table [[braided_length_m, x_m, y_m], ...] (m, machine x and y)"
        table = _speed_table(sec, value, what, key="eccentricity", columns=2)
        return table[0][1:], (table if len(table) > 1 else ())
    return sec.vector("eccentricity", 2, "m, machine x and y", default=(0.0, 0.0)), ()


def _pose_lead(sec: _Section) -> float | None:
    """``"auto"`` (the default) -> None; else a non-negative number (m)."""
    if sec.table.get("pose_lead", "auto") == "auto":
        return None
    return sec.number("pose_lead", 'm, or "auto"', minimum=0.0)


def _take_up_speed(sec: _Section) -> tuple[tuple[float, float], ...]:
    """A number (m/s), or a table [[braided_length_m, speed_m_s], ...] with increasing lengths."""
    what = "a positive number (m/s) or a table [[braided_length_m, speed_m_s], ...]"
    value = sec.raw("take_up_speed", expected=what)
    if isinstance(value, list):
        table = _speed_table(sec, value, what)
    else:
        table = ((0.0, _real(sec, "take_up_speed", value, what, positive=True)),)
    for _, v in table:
        _implausible(sec, "take_up_speed", v, MAX_TAKE_UP_SPEED, "m/s", "mm/s? divide by 1000")
    return table


def _speed_table(sec: _Section, rows: list, what: str, key: str = "take_up_speed",
                 columns: int = 1) -> tuple[tuple[float, ...], ...]:
    """A table over the braided length, [[braided_length_m, value, ...], ...] with ``columns``
    values a row (speeds: positive; an eccentricity's coordinates: any) and strictly
    increasing lengths; the setting between rows is interpolated linearly
    (``stepping.setting_at``)."""
    if not rows:
        raise sec.error(key, rows, f"expected {what}, not an empty list")
    table = []
    for row in rows:
        if not isinstance(row, list) or len(row) != 1 + columns:
            shape = "a pair" if columns == 1 else f"a list of {1 + columns} numbers"
            raise sec.error(key, rows, f"expected {what}; row {_fmt(row)} is not {shape}")
        length = _real(sec, key, row[0], what, minimum=0.0, shown=rows)
        values = [_real(sec, key, v, what, positive=columns == 1, shown=rows) for v in row[1:]]
        table.append((length, *values))
    lengths = [row[0] for row in table]
    if any(b <= a for a, b in zip(lengths, lengths[1:])):
        raise sec.error(key, rows, f"expected {what} with strictly increasing lengths")
    return tuple(table)


def _model(sec: _Section) -> ModelConfig:
    return ModelConfig(
        kind=sec.choice("kind", MODEL_KINDS, default=ModelConfig.kind),
        time_step=sec.number("time_step", "s", default=None, positive=True),
        start=sec.choice("start", STARTS, default=ModelConfig.start),
        seed=sec.integer("seed", "a non-negative integer", default=ModelConfig.seed, minimum=0),
        solver=sec.choice("solver", SOLVERS, default=ModelConfig.solver),
        frontal_iterations=_frontal_iterations(sec),
    )


#: most friction-bound updates a time step may ask for (10 converge the run in the time step
#: on 48-carrier case A; more only cost time)
MAX_FRONTAL_ITERATIONS = 20


def _frontal_iterations(sec: _Section) -> int:
    what = f"an integer from 1 to {MAX_FRONTAL_ITERATIONS} (friction-bound updates a time step)"
    value = sec.integer("frontal_iterations", what, default=ModelConfig.frontal_iterations,
                        minimum=1)
    if value > MAX_FRONTAL_ITERATIONS:
        raise sec.error("frontal_iterations", value, f"expected {what}")
    return value


def _output(sec: _Section, base_dir: Path, name: str) -> OutputConfig:
    value = sec.raw("dir", f"results/{name}")
    if not isinstance(value, str) or not value.strip():
        raise sec.error("dir", value, "expected a folder path string (relative to the config file)")
    return OutputConfig(
        dir=_resolve(value, base_dir),
        field_edge_length=sec.number("field_edge_length", "m", default=None, positive=True),
        snapshots=None if "snapshots" not in sec.table else sec.integer(
            "snapshots", "a non-negative integer", minimum=0),
        input_mesh_fields=_flag(sec, "input_mesh_fields", OutputConfig.input_mesh_fields),
        pictures=_flag(sec, "pictures", OutputConfig.pictures),
    )


def _flag(sec: _Section, key: str, default: bool) -> bool:
    value = sec.raw(key, default)
    if not isinstance(value, bool):
        raise sec.error(key, value, "true or false")
    return value


# ----- echo ----------------------------------------------------------------------------------


def dump_config(config: Config) -> dict:
    """See :func:`_dump_sections`; with ``[[layer]]`` tables also ``"layers"``: layer number
    (from "1") -> its direction and the keys it sets, per section, in file units (a table like
    the sections)."""
    out = _dump_sections(config)
    if config.layers:
        out["layers"] = {str(k): _dump_layer(config, k - 1) for k in range(1, len(config.layers) + 1)}
    return out


def _dump_layer(config: Config, k: int) -> dict:
    """Layer k's direction and its own keys, echoed as :func:`_dump_sections` echoes them."""
    layer = config.layers[k]
    echoed = _dump_sections(config.layer_config(k))
    out = {"direction": layer.direction}
    for sec in LAYER_SECTIONS:
        # a table's companion field is echoed under its key's name (KEY_FIELDS)
        own = [key for key in layer.fields(sec) if key not in COMPANION_FIELDS]
        if own:
            out[sec] = {key: echoed[sec][key] for key in own}
    return out


def _dump_sections(config: Config) -> dict:
    """Plain JSON-able echo of the inputs (for summary.json): file units, degrees, paths as strings.

    Keys and units are those of the TOML file (``angular_speed`` in deg/s); ``take_up_speed``,
    ``angular_speed`` and ``eccentricity`` are the number (pair) when constant, else the table;
    ``trajectory`` and its file's SHA-256 are there only when given. Absent optional values are None; `"material"` is there
    only when the config has the section.
    """
    mc, ma, y, p, mo, out = (config.mandrel, config.machine, config.yarn, config.process,
                             config.model, config.output)
    ring = ma.guide_ring
    speeds = [list(row) for row in p.take_up_speed]
    echo = {
        "source": _str_or_none(config.source),
        "mandrel": {"stl": str(mc.stl), "stl_unit": mc.stl_unit, "centerline": str(mc.centerline),
                    "roll_reference": None if mc.roll_reference is None else list(mc.roll_reference),
                    "body": mc.body},
        "machine": {"carriers": ma.carriers, "spool_radius": ma.spool_radius,
                    "angular_speed": (math.degrees(ma.angular_speed) if not ma.angular_speed_table
                                      else [[length, math.degrees(speed)]
                                            for length, speed in ma.angular_speed_table]),
                    "pattern": ma.pattern,
                    "guide_ring": None if ring is None else {"radius": ring.radius, "offset": ring.offset},
                    "axial_yarns": ma.axial_yarns},
        "yarn": {"width": y.width, "thickness": y.thickness, "tension": y.tension,
                 "friction": y.friction, "ring_friction": y.ring_friction,
                 "friction_law": y.friction_law, "howell_index": y.howell_index,
                 # Howell's keys only under Howell's law (an echo reads back as a config)
                 "howell_reference_force": (y.howell_reference_force
                                            if y.friction_law == "howell" else None),
                 "min_width": y.min_width,
                 "linear_density_tex": y.linear_density_tex, "fibre_density": y.fibre_density,
                 "fibre_radius": y.fibre_radius},
        "process": {"take_up_speed": speeds[0][1] if len(speeds) == 1 else speeds,
                    "initial_position": p.initial_position,
                    "eccentricity": (list(p.eccentricity) if not p.eccentricity_table
                                     else [list(row) for row in p.eccentricity_table]),
                    "braid_length": p.braid_length,
                    "pose_lead": "auto" if p.pose_lead is None else p.pose_lead},
        "model": {"kind": mo.kind, "time_step": mo.time_step, "start": mo.start, "seed": mo.seed,
                  "solver": mo.solver, "frontal_iterations": mo.frontal_iterations},
        "output": None if out is None else {"dir": str(out.dir), "field_edge_length": out.field_edge_length,
                                            "snapshots": out.snapshot_count(mo.kind),
                                            "input_mesh_fields": out.input_mesh_fields,
                                            "pictures": out.pictures},
        "axial_yarn": {"width": config.axial_yarn.width, "thickness": config.axial_yarn.thickness,
                       "linear_density_tex": config.axial_yarn.linear_density_tex},
        "rtm": {"cavity_thickness": config.rtm.cavity_thickness, "permeability": config.rtm.permeability,
                "packing": config.rtm.packing,
                "k_ref": None if config.rtm.k_ref is None else list(config.rtm.k_ref),
                "vf_ref": config.rtm.vf_ref, "table": None if config.rtm.table is None else str(config.rtm.table)},
    }
    if p.trajectory is not None:   # echoed when given, with its digest (a checkpoint's inputs)
        from .trajectory import file_digest

        echo["process"].update(trajectory=str(p.trajectory), trajectory_sha256=file_digest(p.trajectory))
    if ma.carrier_yarns != MachineConfig.carrier_yarns:   # echoed when given, as below
        echo["machine"]["carrier_yarns"] = list(ma.carrier_yarns)
    if config.yarn_types:
        echo["yarn_types"] = {t.name: dict(t.own) for t in config.yarn_types}
    if config.friction_pairs:   # numbered from "1" as the file lists them, like "layers"
        echo["friction_pairs"] = {str(k): {"types": [p_.a, p_.b], "friction": p_.friction}
                                  for k, p_ in enumerate(config.friction_pairs, start=1)}
    if config.material is not None:   # echoed when given (a run without it hashes as before)
        echo["material"] = {"preset": config.material.preset,
                            **{name: getattr(config.material.constituents, name) for name in MATERIAL_CONSTANTS}}
    return echo


def _str_or_none(value) -> str | None:
    return None if value is None else str(value)
