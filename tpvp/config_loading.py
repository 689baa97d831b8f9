"""Building, reading and writing configurations (:mod:`tpvp.config` holds what they are).

Resolutions that the authors' YAML derives from the ground-truth resolution are derived here the
same way, in one place (:data:`DERIVED`, documented in ``docs/configuration.md``): a derived key
that the user does not set follows ``gt_resolution``; a key the user sets wins. Build
configurations with :func:`make_config` (Python keywords or dotted ``key=value`` overrides) or
:func:`load_config` (a YAML file or a named configuration); write the resolved configuration with
:func:`config_yaml` so any result can be re-run exactly. Method, route and look-at-prior names and
the view space are resolved here, at load, through their registries (imported when a configuration
is made, so importing this module loads no stage).
"""

from __future__ import annotations

import dataclasses
import types
import typing
from pathlib import Path

from tpvp.config import PlantConfig, RowConfig
from tpvp.errors import ConfigError, InputFileError
from tpvp.sensor.config import ROW_RANGE

SETTINGS = {"plant": PlantConfig, "row": RowConfig}
# ``realistic``: a robot's view of a plant (issue 49): the planning frame from the previous model and
# the first capture, as a session fixes it, and a wrist RGB-D camera's depth and pose errors.
NAMED = {"paper": ("plant", {}), "paper-row": ("row", {}),
         "realistic": ("plant", {"scene.frame": "previous", "sensor.noise": "arm-rgbd"})}

# Derived parameters: key -> (rule in words, function of the raw settings). A key the user sets
# explicitly wins over its rule. docs/configuration.md has the same table with the authors' names.
DERIVED = {
    "plant": {
        "scene.table_resolution": ("1 x gt_resolution", lambda c: c["gt_resolution"]),
        "scene.reduce_resolution": ("gt_resolution / 2 (large scans only)", lambda c: c["gt_resolution"] / 2),
        "registration.embedded_deformation.node_coverage": ("2 x gt_resolution (nricp_resolution_factor)",
                                                            lambda c: 2 * c["gt_resolution"]),
        "registration.embedded_deformation.seed": ("seed", lambda c: c["seed"]),
        "inflation.step": ("2 x gt_resolution (inflation_resolution_factor)", lambda c: 2 * c["gt_resolution"]),
        "inflation.gamma_near": ("1.5 x gt_resolution (near_current_inflation_distance_factor)",
                                 lambda c: 1.5 * c["gt_resolution"]),
        "inflation.gamma_far": ("2.5 x gt_resolution (far_history_inflation_distance_factor)",
                                lambda c: 2.5 * c["gt_resolution"]),
        "selection.cover_resolution": ("2 x gt_resolution (history_resolution_factor)",
                                       lambda c: 2 * c["gt_resolution"]),
        "gmc.map_resolution": ("1 x gt_resolution (the authors: 2 x, probabilistic map; docs/deviations.md)",
                               lambda c: c["gt_resolution"]),
        "sensor.max_range": ("the view space's range (1.0 m plants)", lambda c: _view_space_range(c["view_space"])),
    },
    "row": {
        "oracle_grid": ("10 x gt_resolution", lambda c: 10 * c["gt_resolution"]),
        "registration.embedded_deformation.seed": ("seed", lambda c: c["seed"]),
        "registration.warp_field.voxel": ("1 x gt_resolution (clouds reduced to voxel centroids)",
                                          lambda c: c["gt_resolution"]),
        "inflation.step": ("1 x gt_resolution (voxel of the morphology)", lambda c: c["gt_resolution"]),
        "inflation.gamma_near": ("1 x gt_resolution", lambda c: c["gt_resolution"]),
        "inflation.gamma_far": ("1 x gt_resolution", lambda c: c["gt_resolution"]),
        "selection.cover_resolution": ("4 x gt_resolution (history_resolution_factor)",
                                       lambda c: 4 * c["gt_resolution"]),
        "sensor.max_range": (f"the view space's range ({ROW_RANGE} m rows)",
                             lambda c: _view_space_range(c["view_space"])),
        "pose_noise.seed": ("seed", lambda c: c["seed"]),
    },
}


def _view_space_range(spec, config=None) -> float:
    """The range of the view space ``spec``; given the ``config`` it belongs to, resolved there once
    (``config.space``)."""
    from tpvp.viewspace.space import get_view_space  # a view space is resolved at load, not at import

    if not isinstance(spec, str):
        raise ConfigError(f"configuration key 'view_space': expected a name or a file path, got {spec!r}")
    try:
        return float((get_view_space(spec) if config is None else config.space).max_range)
    except (ConfigError, InputFileError) as exc:
        raise ConfigError(f"configuration key 'view_space': {exc}") from None


# --------------------------------------------------------------------------------------------------
# dataclass <-> nested dict
# --------------------------------------------------------------------------------------------------


def to_dict(config) -> dict:
    """Nested plain dict of a configuration (every value explicit)."""
    out = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        out[f.name] = to_dict(value) if dataclasses.is_dataclass(value) else value
    return out


def flatten_keys(tree: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(flatten_keys(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def _as_tuple(value) -> tuple:
    """A YAML list (of lists) as the tuple (of tuples) a frozen configuration holds."""
    return tuple(_as_tuple(v) if isinstance(v, (list, tuple)) else v for v in value)


def _coerce(key: str, value, hint):
    """``value`` checked against the field's type hint (int -> float allowed, ``X | None``, a list
    for a tuple; the section checks the tuple's items)."""
    options = typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, types.UnionType) else (hint,)
    for option in options:
        if option is type(None) and value is None:
            return None
        if option is bool and isinstance(value, bool):
            return value
        if option is int and isinstance(value, int) and not isinstance(value, bool):
            return value
        if option is float and isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        if option is str and isinstance(value, str):
            return value
        if option is tuple and isinstance(value, (list, tuple)):
            return _as_tuple(value)
    words = {bool: "true or false", int: "an integer", float: "a number", str: "a string", type(None): "null",
             tuple: "a list"}
    expected = " or ".join(words.get(o, getattr(o, "__name__", str(o))) for o in options)
    raise ConfigError(f"configuration key {key!r}: expected {expected}, got {value!r}")


def _build(cls, values: dict, prefix: str, defaults):
    """Construct ``cls`` from a flat dict of dotted keys below ``prefix`` over ``defaults``."""
    kwargs = {}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        key = f"{prefix}{f.name}"
        default = getattr(defaults, f.name)
        if dataclasses.is_dataclass(default):
            kwargs[f.name] = _build(type(default), values, f"{key}.", default)
        else:
            kwargs[f.name] = _coerce(key, values[key], hints[f.name]) if key in values else default
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        where = prefix.rstrip(".") or "configuration"
        if str(exc).startswith(f"{where}."):  # the message names its key already
            raise
        raise ConfigError(f"{where}: {exc}") from None


def _known_keys(cls) -> set:
    return set(flatten_keys(to_dict(cls())))


def with_overrides(config, overrides: dict):
    """``config`` (a resolved configuration) with dotted-key ``overrides`` applied, checked and
    coerced as :func:`make_config` does; every other value stays as it is (nothing re-derived)."""
    if not overrides:
        return config
    setting = next(name for name, cls in SETTINGS.items() if isinstance(config, cls))
    return make_config(setting, flatten_keys(to_dict(config)) | dict(overrides))


def make_config(setting: str = "plant", overrides: dict | None = None, **keywords):
    """A resolved configuration of ``setting`` (``plant`` or ``row``) with dotted-key ``overrides``
    (``{"registration.embedded_deformation.iterations": 100}``) and top-level ``keywords``
    (``gt_resolution=0.001``). Derived keys not given follow their rule (:data:`DERIVED`); unknown
    keys and bad values are one :class:`ConfigError` line naming the key."""
    if setting not in SETTINGS:
        raise ConfigError(f"unknown setting {setting!r}; choose one of {', '.join(SETTINGS)}")
    cls = SETTINGS[setting]
    given = dict(overrides or {})
    for key, value in keywords.items():
        if dataclasses.is_dataclass(value):
            given.update({f"{key}.{k}": v for k, v in flatten_keys(to_dict(value)).items()})
        else:
            given[key] = value
    given.pop("setting", None)
    known = _known_keys(cls)
    for key in given:
        if key not in known:
            close = sorted(k for k in known if k.split(".")[-1] == key.split(".")[-1])
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise ConfigError(f"unknown configuration key {key!r} for the {setting} setting{hint}")
    base = to_dict(cls())
    raw = {**flatten_keys(base), **given}
    for key, (_, rule) in DERIVED[setting].items():
        if key not in given:
            raw[key] = rule(raw)
    config = _build(cls, raw, "", cls())
    _check_methods(config)
    return config


def _check_methods(config) -> None:
    """Method names must be registered (the registries import their packages lazily)."""
    from tpvp.nbv.methods import NBV_METHODS  # registries load at make_config, not at import
    from tpvp.registration.methods import REGISTRATION_METHODS  # a registry loads its plugins: at load
    from tpvp.setcover.methods import SELECTION_METHODS  # a registry loads its plugins: at load
    from tpvp.sensor.noise import NOISE_PROFILES  # the noise profiles' registry: at load

    for registry, name, key in ((NBV_METHODS, config.nbv.method, "nbv.method"),
                                (REGISTRATION_METHODS, config.registration.method, "registration.method"),
                                (SELECTION_METHODS, config.selection.method, "selection.method"),
                                (NOISE_PROFILES, config.sensor.noise, "sensor.noise")):
        if name not in registry:
            raise ConfigError(f"configuration key {key!r}: unknown {registry.kind} {name!r}; "
                              f"choose one of {', '.join(registry.names())}")
    if isinstance(config, RowConfig):
        _check_row_names(config)
    _view_space_range(config.view_space, config)


def _check_row_names(config) -> None:
    """A row's look-at prior and route must be registered (one line naming the choices)."""
    from tpvp.path.route import ROW_ROUTES  # the route registry loads the path solvers
    from tpvp.viewspace.priors import LOOK_AT_PRIORS  # the prior registry loads the view spaces

    try:
        LOOK_AT_PRIORS.get(config.candidates)
        ROW_ROUTES.get(config.route)
    except ConfigError as exc:
        raise ConfigError(f"configuration: {exc}") from None


def parse_overrides(items) -> dict:
    """``["a.b=1", "c=true"]`` -> ``{"a.b": 1, "c": True}`` (values read as YAML scalars)."""
    import yaml

    out = {}
    for item in items or ():
        key, sep, text = str(item).partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r}: write key=value, e.g. --set registration.embedded_deformation.iterations=100")
        try:
            value = yaml.safe_load(text) if text.strip() else None
        except yaml.YAMLError:
            value = text
        if isinstance(value, (dict, list)):
            raise ConfigError(f"--set {item!r}: the value must be a single number, word or true/false")
        out[key.strip()] = value
    return out


def load_config(source: str | Path | None = "paper", overrides: dict | None = None):
    """A named configuration (``paper``, ``paper-row``) or a YAML file, plus dotted ``overrides``.

    The file may give ``setting: plant|row`` and ``base: paper`` and any keys, nested or dotted.
    A resolved file written by :func:`config_yaml` loads back to the same configuration.
    """
    import yaml

    source = "paper" if source is None else source
    if str(source) in NAMED:
        setting, values = NAMED[str(source)]
        values = {**values, "name": str(source)}
    else:
        path = Path(source)
        if not path.is_file():
            raise InputFileError(f"configuration {str(source)!r} is neither one of {', '.join(NAMED)} nor an existing file")
        try:
            tree = yaml.safe_load(path.read_text())
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise InputFileError(f"{path}: not a readable YAML configuration ({first})") from None
        tree = {} if tree is None else tree
        if not isinstance(tree, dict):
            raise InputFileError(f"{path}: a configuration must be a mapping of keys to values")
        tree.pop("provenance", None)
        base = tree.pop("base", None)
        setting = tree.pop("setting", None)
        if base is not None:
            if base not in NAMED:
                raise ConfigError(f"{path}: base {base!r} is not one of {', '.join(NAMED)}")
            base_setting, base_values = NAMED[base]
            setting = setting or base_setting
            values = {**base_values, **flatten_keys(tree)}
        else:
            values = flatten_keys(tree)
        setting = setting or "plant"
    return make_config(setting, {**values, **(overrides or {})})


def config_yaml(config, header: str = "") -> str:
    """The fully resolved configuration as YAML (loads back with :func:`load_config`)."""
    import yaml

    tree = {"setting": config.setting, **to_dict(config)}
    lines = [f"# {line}" for line in header.splitlines()] if header else []
    return "\n".join(lines + [yaml.safe_dump(tree, sort_keys=False, default_flow_style=False)])


def derived_table(setting: str = "plant") -> list[tuple[str, str]]:
    """``(key, rule)`` of every derived parameter of ``setting``."""
    return [(key, rule) for key, (rule, _) in DERIVED[setting].items()]
