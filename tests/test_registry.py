"""The one name map: spellings, configuration checks, models of your own, entry points."""

from __future__ import annotations

import importlib
import importlib.metadata
import sys
from pathlib import Path

import numpy as np
import pytest

import isoflow as iso
from isoflow import registry
from isoflow.io.rebuild import check_recorded_model, check_recorded_state
from isoflow.registry import ConfigError

BASE = {"model": "rigid-body", "params": {"n": 4}, "dt": 0.1, "n_steps": 10}


def test_every_method_spelling_builds_its_method() -> None:
    for name, spec in registry.METHODS.items():
        method = registry.make_method(name)
        assert isinstance(method, iso.Method)
        assert bool(method.implicit) == spec.implicit, name
    assert registry.make_method("isosyrk-2").order == 4
    assert registry.make_method("isomp-kahan-li-8").order == 8
    assert isinstance(registry.make_method("rk4"), iso.RK4)


def test_solvers_and_anderson() -> None:
    fp = registry.make_solver("fixed-point", rtol=1e-12, anderson=3)
    assert isinstance(fp, iso.FixedPoint) and fp.anderson == 3 and fp.rtol == 1e-12
    assert registry.make_solver("newton").jacobian == "dense"
    assert registry.make_solver("newton-krylov").jacobian == "krylov"
    with pytest.raises(ConfigError, match="option of the fixed-point solver"):
        registry.make_solver("newton", anderson=2)
    _, _, method, _ = registry.build(BASE | {"solver": "fixed-point", "anderson": 2})
    assert method.solver.anderson == 2


def test_normalized_configuration_is_complete_and_stable() -> None:
    cfg = registry.normalize_config(BASE)
    assert cfg == {
        "model": "rigid-body", "params": {"n": 4}, "method": "isomp", "solver": "fixed-point",
        "rtol": None, "anderson": 0, "t0": 0.0, "save_every": 1, "dt": 0.1, "n_steps": 10,
    }  # fmt: skip
    assert registry.normalize_config(cfg) == cfg
    rk = registry.normalize_config(BASE | {"method": "rk4"})
    assert "solver" not in rk and "anderson" not in rk
    # older model spellings are read, and written as the one name
    assert registry.normalize_config(BASE | {"model": "rigid_body"})["model"] == "rigid-body"


@pytest.mark.parametrize(
    ("change", "error", "pattern"),
    [
        ({"params": 3}, ConfigError, r"params must be a table"),
        ({"dt": "0.1"}, ConfigError, r"dt must be a number, got '0.1'"),
        ({"n_steps": 2.5}, ConfigError, r"n_steps must be an integer"),
        ({"save_every": True}, ConfigError, r"save_every must be an integer"),
        ({"params": {"n": 100000}}, ConfigError, r"rigid-body n must be <= 2048"),
        ({"params": {"n": "6"}}, ConfigError, r"rigid-body n must be an integer"),
        ({"params": {"N": 3}}, ConfigError, r"model 'rigid-body' has no parameter 'N'"),
        ({"method": "rk4", "solver": "newton"}, ConfigError, r"'rk4' is explicit"),
        ({"method": "rk4", "rtol": 1e-10}, ConfigError, r"'rk4' is explicit"),
        ({"solver": "newton", "anderson": 2}, ConfigError, r"option of the fixed-point"),
        ({"anderson": 9}, ConfigError, r"anderson must be in 0..8"),
        ({"method": "IsoMP"}, ConfigError, r"unknown method 'IsoMP'; write 'isomp'"),
        ({"method": "spherical midpoint"}, ConfigError, r"write 'spherical-midpoint'"),
        ({"solver": "anderson"}, ConfigError, r"unknown solver 'anderson'"),
        ({"model": 7}, ConfigError, r"model must be a name"),
        ({"model": "not a:spec"}, ConfigError, r"package.module:function"),
        ({"colour": 3}, ConfigError, r"unknown option\(s\) colour"),
        ({"rtol": -1.0}, ConfigError, r"rtol must be positive"),
        ({"dt": 0.3, "n_steps": None, "t1": 1.0}, iso.StepSizeError, r"not a whole number"),
        ({"t1": 1.0}, iso.ParameterError, r"exactly two of t1, dt and n_steps"),
    ],
)
def test_configuration_mistakes_are_one_line_typed_errors(change, error, pattern) -> None:
    cfg = {k: v for k, v in (BASE | change).items() if v is not None}
    with pytest.raises(error, match=pattern) as info:
        registry.normalize_config(cfg)
    assert "\n" not in str(info.value)


def test_config_from_toml_checks_out() -> None:
    with pytest.raises(ConfigError, match="out must be a file name"):
        registry.config_from_toml({"model": "rigid-body", "out": 7})
    cfg, out = registry.config_from_toml({"model": "rigid-body", "out": "a.h5"})
    assert out == "a.h5" and "out" not in cfg
    with pytest.raises(
        ConfigError, match=r"unknown option\(s\) foo \(known: .*n_steps, out, params"
    ):
        registry.config_from_toml({"model": "rigid-body", "foo": 1})  # a TOML file takes out
    spins = registry.MODELS["spin-chain"].params["noise_seed"].help
    assert spins.endswith("(required with temperature > 0)")


def test_size_bounds_refuse_before_building(monkeypatch: pytest.MonkeyPatch) -> None:
    called = []
    monkeypatch.setattr(registry.ModelSpec, "make", lambda self, p: called.append(p))
    for cfg in (
        BASE | {"params": {"n": 100000}},
        BASE | {"model": "spin-chain", "params": {"N": 10**9}},
        BASE | {"model": "euler-sphere", "params": {"N": 100000}},
        BASE | {"model": "spin-lattice", "params": {"shape": [10**5, 10**5]}},
        BASE | {"model": "mhd-sphere", "params": {"N": 4096}},
    ):
        with pytest.raises(ConfigError, match="must be <="):
            registry.build(cfg)
    assert called == []


def test_list_parameters() -> None:
    spec = registry.MODELS["spin-lattice"]
    assert registry.parse_param(spec, "shape", "6,5") == [6, 5]
    assert registry.parse_param(spec, "field", "[0, 0, 0.5]") == [0.0, 0.0, 0.5]
    with pytest.raises(ConfigError, match="list of 3"):
        registry.parse_param(spec, "field", "1,2")
    problem, y0, _, _ = registry.build(
        {"model": "spin-lattice", "params": {"shape": [3, 4]}, "dt": 0.1, "n_steps": 1}
    )
    assert y0.shape == (12, 3) and problem.algebra.name == "(R^3, x)^12"


def test_every_builtin_model_builds_with_its_defaults_and_checks_them() -> None:
    small = {
        "rigid-body": {"n": 3}, "brockett": {"n": 3}, "toda": {"n": 3}, "spin-chain": {"N": 4},
        "euler-sphere": {"N": 4}, "spin-lattice": {"shape": [3, 3]}, "mhd-sphere": {"N": 4},
    }  # fmt: skip
    for name, spec in registry.MODELS.items():
        cfg = {"model": name, "params": small.get(name, {}), "dt": 0.01, "n_steps": 2}
        problem, y0, method, kw = registry.build(cfg)
        sol = iso.solve(problem, method, y0, **kw, progress=False)
        assert sol.success, name
        for key, p in (spec.params or {}).items():
            assert p.help and (p.kind in (int, float, str, bool)), (name, key)


def test_untyped_factory_parameters_are_toml_values() -> None:
    spec = registry.ModelSpec("pkg.mod:f", lambda **kw: None)
    assert registry.parse_param(spec, "k", "3") == 3
    assert registry.parse_param(spec, "x", "0.5") == 0.5
    assert registry.parse_param(spec, "flag", "true") is True
    assert registry.parse_param(spec, "v", "[1, 2]") == [1, 2]
    assert registry.parse_param(spec, "name", "curve") == "curve"
    cfg = registry.normalize_config(BASE | {"model": "pkg.mod:f", "params": {"a": [1, 2.5]}})
    assert cfg["params"] == {"a": [1, 2.5]}
    with pytest.raises(ConfigError, match="must be finite"):
        registry.normalize_config(BASE | {"model": "pkg.mod:f", "params": {"a": float("nan")}})


def test_a_configuration_never_imports_a_model(monkeypatch: pytest.MonkeyPatch) -> None:
    imported: list[str] = []
    real = importlib.import_module
    monkeypatch.setattr(importlib, "import_module", lambda n, *a: imported.append(n) or real(n, *a))
    monkeypatch.setattr(
        importlib.metadata, "entry_points", lambda **kw: pytest.fail("read entry points")
    )
    sys.modules.pop("user_models", None)
    cfg = BASE | {"model": "user_models:toy_rigid_body", "params": {"n": 3}}
    assert registry.normalize_config(cfg)["model"] == "user_models:toy_rigid_body"
    with pytest.raises(ConfigError, match=r"not built in.*--model user_models:toy_rigid_body"):
        registry.build(cfg)
    with pytest.raises(ConfigError, match="not built in"):
        registry.build(BASE | {"model": "toy"})  # an entry-point name
    assert "user_models" not in sys.modules and imported == []


def test_user_factory_by_import_path() -> None:
    spec = registry.load_model("user_models:toy_rigid_body")
    assert spec.name == "user_models:toy_rigid_body" and spec.params is None and not spec.builtin
    cfg = registry.normalize_config(BASE | {"model": spec.name, "params": {"n": 5}}, model=spec)
    problem, y0, method, kw = registry.build(cfg, model=spec)
    assert y0.shape == (5, 5) and problem.algebra.name == "so(5)"
    sol = iso.solve(problem, method, y0, **kw, progress=False)
    assert sol.success and sol.diagnostics.casimir_drift < 1e-13


@pytest.mark.parametrize(
    ("name", "pattern"),
    [
        ("no_such_module_xyz:f", r"cannot import 'no_such_module_xyz'"),
        ("user_models:missing", r"has no attribute 'missing'"),
        ("user_models:TOY_SPEC.nothing", r"has no attribute"),
        ("pendulum", r"unknown model 'pendulum'"),
    ],
)
def test_load_model_mistakes(name: str, pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        registry.load_model(name)


def test_factory_results_and_arguments_are_checked() -> None:
    spec = registry.load_model("user_models:not_a_model")
    with pytest.raises(ConfigError, match=r"must return \(problem, initial_state\)"):
        spec.make({})
    spec = registry.load_model("user_models:toy_rigid_body")
    with pytest.raises(ConfigError, match="unexpected keyword argument 'colour'"):
        spec.make({"colour": 3})


def _fake_entry_points(monkeypatch: pytest.MonkeyPatch, **targets: str) -> None:
    eps = [
        importlib.metadata.EntryPoint(name, value, registry.ENTRY_POINT_GROUP)
        for name, value in targets.items()
    ]

    def entry_points(**kw):
        assert kw == {"group": registry.ENTRY_POINT_GROUP}
        return eps

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)


def test_entry_point_models(monkeypatch: pytest.MonkeyPatch) -> None:
    _fake_entry_points(monkeypatch, toy="user_models:TOY_SPEC", plain="user_models:toy_rigid_body")
    spec = registry.load_model("toy")
    assert spec.name == "toy" and set(spec.params) == {"n", "scale", "seed"} and not spec.builtin
    with pytest.raises(ConfigError, match="toy n must be <= 64"):
        registry.normalize_config(BASE | {"model": "toy", "params": {"n": 65}}, model=spec)
    _, y0, _, _ = registry.build(BASE | {"model": "toy", "params": {"n": 3}}, model=spec)
    assert y0.shape == (3, 3)
    assert registry.load_model("plain").params is None
    names = [row[0] for row in registry.describe("models")]
    assert "toy" in names and "plain" in names and "rigid-body" in names


def test_recorded_model_check() -> None:
    spec = registry.load_model("user_models:toy_rigid_body")
    recorded = registry.normalize_config(
        BASE | {"model": spec.name, "params": {"n": 3, "seed": 2}}, model=spec
    )
    assert check_recorded_model(recorded, spec, {"n": 3})["params"] == {"n": 3, "seed": 2}
    with pytest.raises(ConfigError, match="written by model 'user_models:toy_rigid_body', not"):
        check_recorded_model(recorded, registry.load_model("user_models:compiled_toy"))
    with pytest.raises(ConfigError, match="n = 4 differs from the run's n = 3"):
        check_recorded_model(recorded, spec, {"n": 4})
    problem, y0, _, _ = registry.build(recorded, model=spec)
    check_recorded_state({"algebra": "so(3)", "state_shape": [3, 3]}, problem, y0)
    with pytest.raises(ConfigError, match="file's run was on so"):
        check_recorded_state({"algebra": "so(4)", "state_shape": [4, 4]}, problem, y0)
    with pytest.raises(ConfigError, match="shape"):
        check_recorded_state({"algebra": "so(3)", "state_shape": [2, 3, 3]}, problem, y0)


def test_resume_of_a_user_model_file_imports_nothing(tmp_path: Path) -> None:
    from isoflow import io

    spec = registry.load_model("user_models:toy_rigid_body")
    cfg = registry.normalize_config(BASE | {"model": spec.name, "n_steps": 20}, model=spec)
    problem, y0, method, kw = registry.build(cfg, model=spec)
    path = tmp_path / "user.h5"
    iso.solve(problem, method, y0, **kw, progress=False, writer=io.HDF5Writer(path, cfg))
    sys.modules.pop("user_models", None)
    with pytest.raises(ConfigError, match="not built in"):
        io.resume(path)
    assert "user_models" not in sys.modules
    # named again by the caller: resumes (a complete run changes nothing)
    sol = io.resume(path, problem=problem, method=method)
    assert sol.success and np.array_equal(io.load(path).ys[-1], sol.ys[-1])
    # or by its name (its module imported now), parameters given again checked against the file
    with pytest.raises(ConfigError, match=r"parameter n = 5 differs from the run's n = 4"):
        io.resume(path, model=spec.name, params={"n": 5})
    with pytest.raises(ConfigError, match=r"written by model 'user_models:toy_rigid_body', not"):
        io.resume(path, model="user_models:compiled_toy")
    with pytest.raises(iso.ParameterError, match=r"^model= and params= rebuild the run's problem"):
        io.resume(path, problem=problem, method=method, model=spec)
    sol = io.resume(path, model=spec.name, params={"n": 4})
    assert sol.success and sol.ys[-1].tobytes() == io.load(path).ys[-1].tobytes()


def test_layered_config_puts_the_options_over_the_file(tmp_path: Path) -> None:
    f = tmp_path / "run.toml"
    f.write_text(
        'model = "toda"\nmethod = "rk4"\nt1 = 1.0\ndt = 0.1\nout = "a.h5"\n'
        "[params]\nn = 5\nseed = 3\n"
    )
    spec, cfg, out = registry.layered_config(
        f, params=[("n", "7"), ("n", "6")], options={"dt": 0.05, "method": None}
    )
    assert spec is registry.MODELS["toda"] and out == "a.h5"
    assert cfg["params"] == {"n": 6, "seed": 3} and cfg["method"] == "rk4"
    assert (cfg["t1"], cfg["dt"]) == (1.0, 0.05)
    _, cfg, _ = registry.layered_config(f, options={"dt": 0.2, "n_steps": 3})
    assert "t1" not in cfg and (cfg["dt"], cfg["n_steps"]) == (0.2, 3)  # two replace two
    _, cfg, _ = registry.layered_config(f, model="rigid-body")  # the file's params are toda's
    assert cfg["model"] == "rigid-body" and cfg["params"] == {"n": 10}
    with pytest.raises(ConfigError, match=r"toda n must be an integer, got 'six'"):
        registry.layered_config(f, params=[("n", "six")])
    with pytest.raises(ConfigError, match=r"^name a model \(isoflow run MODEL"):
        registry.layered_config(None)
    with pytest.raises(ConfigError, match=r"no such configuration file$"):
        registry.layered_config(tmp_path / "missing.toml", model="toda")


def test_experiment_names() -> None:
    from isoflow.experiments import EXPERIMENTS

    assert list(EXPERIMENTS) == list(registry.EXPERIMENTS)
    for name, experiment in EXPERIMENTS.items():
        assert experiment.name == name and experiment.description
        assert registry.get_experiment(name) is experiment
    with pytest.raises(ConfigError, match="unknown experiment"):
        registry.get_experiment("spin-chain-errors")


# ---- parameters that only set the initial state (ModelSpec.initial, used by sweeps) ------------

#: Small sizes, and for each initial-data parameter a value other than the base one.
_INITIAL_CASES = {
    "rigid-body": ({"n": 4}, {}),
    "brockett": ({"n": 4}, {"seed": 3, "scale": 2.5}),
    "toda": ({"n": 5}, {"seed": 3}),
    "spin-chain": ({"N": 6, "initial": "random"}, {"initial": "curve", "seed": 3}),
    "hyperbolic-vortices": ({}, {}),
    "spin-lattice": ({"shape": [3, 4]}, {"initial": "ferro", "seed": 3}),
    "euler-sphere": (
        {"N": 6},
        {"seed": 3, "lmin": 2, "lmax": 4, "slope": -1.0, "rms": 2.0},
    ),
    "qg-sphere": (
        {"N": 6, "lamb": 2.0, "omega": 1.0},
        {"seed": 3, "lmin": 2, "lmax": 4, "slope": -1.0, "rms": 2.0},
    ),
    "mhd-sphere": (
        {"N": 6},
        {
            "seed": 3,
            "lmin": 2,
            "lmax": 4,
            "slope": -1.0,
            "kinetic_energy": 0.1,
            "magnetic_energy": 0.4,
        },
    ),
    "heavy-top": ({"top": "kovalevskaya"}, {"M0": [0.1, 0.2, 0.3], "Gamma0": [0.0, 0.6, 0.8]}),
}


def _same_value(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same_value(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_same_value(x, y) for x, y in zip(a, b, strict=True))
    if callable(a) and callable(b):
        return a is b or getattr(a, "__qualname__", 1) == getattr(b, "__qualname__", 2)
    return bool(a == b)


def _same_dynamics(p: iso.IsospectralProblem, q: iso.IsospectralProblem, rng) -> bool:
    """``B``, ``H``, the invariants and the kernel of two problems agree (at random states)."""
    if p.algebra.name != q.algebra.name or (p.kernel is None) != (q.kernel is None):
        return False
    if p.kernel is not None and not (
        type(p.kernel) is type(q.kernel) and _same_value(vars(p.kernel), vars(q.kernel))
    ):
        return False
    if set(p.invariants) != set(q.invariants) or (p.hamiltonian is None) != (q.hamiltonian is None):
        return False
    for _ in range(2):
        W = p.algebra.random(rng)
        if not np.array_equal(p.evaluate_B(W), q.evaluate_B(W)):
            return False
        if p.hamiltonian is not None and not np.array_equal(p.hamiltonian(W), q.hamiltonian(W)):
            return False
        for k in p.invariants:
            if not np.array_equal(p.invariants[k](W), q.invariants[k](W)):
                return False
    return True


@pytest.mark.parametrize("name", sorted(registry.MODELS))
def test_initial_parameters_change_only_the_initial_state(name: str) -> None:
    spec = registry.MODELS[name]
    base, changed = _INITIAL_CASES[name]
    assert set(changed) == set(spec.initial), "every initial-data parameter is exercised"
    p0, y0 = spec.make(base)
    for key, value in changed.items():
        p1, y1 = spec.make(base | {key: value})
        assert not np.array_equal(np.asarray(y0), np.asarray(y1)), f"{key} does not change y0"
        rng = np.random.default_rng(0)
        assert _same_dynamics(p0, p1, rng), f"{name}: {key} changes the dynamics"


@pytest.mark.parametrize(
    ("name", "base", "key", "value"),
    [("brockett", {"n": 4}, "n", 5), ("euler-sphere", {"N": 6}, "omega", 1.0),
     ("spin-lattice", {"shape": [3, 4]}, "J", 2.0), ("hyperbolic-vortices", {}, "config", 2),
     ("mhd-sphere", {"N": 6}, "omega", 1.0), ("heavy-top", {}, "mgl", 2.0)],
)  # fmt: skip
def test_the_dynamics_check_can_fail(name: str, base: dict, key: str, value: object) -> None:
    spec = registry.MODELS[name]
    assert key not in spec.initial
    p0, _ = spec.make(base)
    p1, _ = spec.make(base | {key: value})
    assert not _same_dynamics(p0, p1, np.random.default_rng(0))
