"""Shared test configuration: pin BLAS to one thread so timings stay sane on a busy 2-core box,
and keep numba's on-disk cache (``.numba_cache``) true to the sources.

numba's cache checks only the file that defines a function: a compiled loop that inlines a
block from another module (every stage inlines its layout's blocks) is loaded stale from the
cache after that block changes. So the cache is emptied whenever the compiled layer's sources
differ from those it was filled from (a digest in ``.numba_cache/SOURCES``), once per test
session (by the controlling process, before any worker starts).
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings
from threadpoolctl import threadpool_limits

#: Whether the cache is this repository's own (a cache the user chose is left alone).
_OWN_CACHE = "NUMBA_CACHE_DIR" not in os.environ
os.environ.setdefault(
    "NUMBA_CACHE_DIR", os.path.join(os.path.dirname(__file__), "..", ".numba_cache")
)

#: The sources whose functions other modules' compiled code inlines.
_INLINED = ("_compiled", "_kernel_fields.py", "sphere/compiled.py")


def _compiled_sources_digest() -> str:
    src = Path(__file__).resolve().parent.parent / "src" / "isoflow"
    files: list[Path] = []
    for name in _INLINED:
        p = src / name
        files.extend(sorted(p.rglob("*.py")) if p.is_dir() else [p] if p.exists() else [])
    h = hashlib.sha256()
    for f in files:
        h.update(str(f.relative_to(src)).encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


def pytest_configure(config: pytest.Config) -> None:
    if not _OWN_CACHE or os.environ.get("PYTEST_XDIST_WORKER"):  # the controller did it
        return
    cache = Path(os.environ["NUMBA_CACHE_DIR"])
    stamp = cache / "SOURCES"
    digest = _compiled_sources_digest()
    if stamp.exists() and stamp.read_text().strip() == digest:
        return
    if cache.exists():
        shutil.rmtree(cache, ignore_errors=True)
    cache.mkdir(parents=True, exist_ok=True)
    stamp.write_text(digest + "\n")


_limits = threadpool_limits(limits=1)

settings.register_profile(
    "ci", max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("ci")


#: Tests marked ``slow`` here rather than in their files: cases of a parametrization (by their
#: ids) and whole modules. Each took over a minute in a full run on the loaded 2-core machine
#: (about 10-40 s quiet); ``pytest -m slow`` runs them (CI does), the default run leaves them out.
#: Each property they check keeps a fast case in the default run where one exists (one layout of
#: the toy method, one compiled case per layout family, the experiments' figures).
SLOW = (
    "tests/test_experiments.py::",
    # two fresh processes compiling the dense BLAS loops on a new cache (about a minute)
    "tests/test_compile_context.py::",
    "tests/test_sweep.py::test_every_member_equals_a_serial_solve[mhd-sphere]",
    "tests/test_sweep.py::test_every_member_equals_a_serial_solve[perturbed-heavy-top]",
    "tests/test_sweep.py::test_client_killed_and_restarted_finishes_like_an_uninterrupted_run",
    "tests/test_sweep.py::test_a_task_whose_members_all_failed_is_frozen_at_its_last_good_state",
    "tests/test_semidirect.py::test_compiled_pairs_equal_the_numpy_path[so4]",
    "tests/test_semidirect.py::test_compiled_pairs_equal_the_numpy_path[su3]",
    "tests/test_semidirect.py::test_compiled_pairs_equal_the_numpy_path[su20-blas]",
    "tests/test_registry.py::test_every_builtin_model_builds_with_its_defaults_and_checks_them",
    "tests/test_cli_user_model.py::test_user_model_streams_and_resumes_bit_for_bit_when_named",
    "tests/test_cli_user_model.py::test_user_compiled_model_from_toml",
    "tests/test_cli_app.py::test_run_with_anderson_and_an_old_spelling",
    "tests/test_isomp.py::test_state_stays_in_space_over_1e5_steps",
    "tests/test_euler_sphere.py::test_casimirs_at_rounding_over_many_steps[64-1.0-0.05-10000]",
    "tests/test_compiled.py::test_compiled_equals_numpy[rigid ensemble 20 (blocks)]",
    "tests/test_compiled.py::test_compiled_equals_numpy[rigid ensemble 5 (members)]",
    "tests/test_compiled.py::test_compiled_equals_numpy[CompiledB u(7) ensemble 4]",
    "tests/test_compiled.py::test_compiled_equals_numpy[su(5) ensemble 12 (blocks)]",
    "tests/test_compiled.py::test_compiled_equals_numpy[u(40) BLAS]",
    "tests/test_compiled.py::test_compiled_equals_numpy[CompiledB so(36) BLAS]",
    "tests/test_compiled.py::test_compiled_equals_numpy[sphere vortices ensemble]",
    # measured quiet from a fresh clone (cold numba cache, 2026-11-26): the first case of a
    # compiled family pays its compilation, 10-60 s each; a cheaper case of each family stays
    *(
        f"tests/test_compiled.py::test_planar_3m_stage_equals_numpy_and_the_complex_tiles[{c}]"
        for c in ("su(40)", "euler_sphere su(48)", "CompiledB su(34)")
    ),
    *(
        f"tests/test_compiled.py::test_compiled_equals_numpy[{c}]"
        for c in (
            "rigid ensemble 20, Anderson",
            "sphere vortices",
            "brockett herm(6) in a frame, ensemble 10",
            "CompiledB herm(6) Anderson",
            "CompiledB (R^3, x)^6 ensemble",
            "CompiledB (R^3, x_L)^6",
            "spin chain ensemble 3 (fused)",
        )
    ),
    "tests/test_compiled.py::test_threaded_ensembles_equal_serial",
    "tests/test_compiled.py::test_chunks_give_the_same_run_bit_for_bit[rigid ensemble 20 (blocks)]",
    *(
        f"tests/test_docs_snippets.py::test_documentation_page_runs[docs/user_guide/{page}.rst]"
        for page in ("forced", "noise", "qg", "spaces")
    ),
    *(
        f"tests/test_docs_snippets.py::test_docstring_examples_run[isoflow.{mod}]"
        for mod in (
            "methods.strang",
            "models._spin_lattice",
            "models._qg_sphere",
            "models._euler_sphere",
        )
    ),
    "tests/test_noise.py::test_stochastic_vortices_and_sphere_keep_their_casimirs_on_every_path",
    "tests/test_noise.py::test_the_chains_fused_stochastic_sweep_takes_the_numpy_paths_steps",
    "tests/test_noise_spins.py::test_thermal_chain_keeps_every_spin_length_per_path",
    "tests/test_sweep.py::test_every_member_equals_a_serial_solve[brockett]",
    "tests/test_semidirect.py::test_compiled_pairs_with_anderson_and_the_heavy_top_equal_the_numpy",
    "tests/test_restart_layouts.py::test_a_kill_at_any_write_resumes_bit_for_bit[su(5) blocked",
    "tests/test_restart_layouts.py::test_a_kill_at_any_write_resumes_bit_for_bit[su(17) x| su(17)*",
    "tests/test_resume.py::test_sigkill_then_resume_is_bit_for_bit",
    "tests/test_forced.py::test_split_step_on_the_planar_layout_matches_the_numpy_path",
    # measured from a fresh clone with a compile recorder (2026-11-26): the first run of a
    # driver signature (layout x stage x field x dtype, serial or parallel) compiles for
    # 10-16 s. Each case below was the only default-run user of its signature (or of the
    # complex BLAS family's), and its property keeps a case in the default run: the NumPy
    # twin of a compiled/numpy pair, the su(N) real planes for the BLAS stages, the heavy top
    # for the pairs, the (R^3, x)^N particles and CompiledB so(8) for user fields, the member
    # that leaves the space for ensemble failures, one temperature per thermal check.
    "tests/test_experiment_figures.py::",  # 12 signatures; the experiments themselves are slow
    *(
        f"tests/test_forced.py::{t}[compiled]"
        for t in (
            "test_double_bracket_keeps_the_spectrum_and_dissipates_energy",
            "test_a_users_linear_part_and_forcing_go_through_the_same_hook",
            "test_split_step_with_B_zero_is_the_exact_flow",
            "test_a_time_dependent_forcing_is_second_order",
        )
    ),
    "tests/test_model_brockett.py::test_ensemble_equals_separate_runs[fixed]",
    "tests/test_mhd_sphere.py::test_compiled_equals_numpy[",
    "tests/test_mhd_sphere.py::test_both_casimir_families_at_rounding_and_the_energy_bounded[24-",
    "tests/test_compensated.py::test_increments_below_the_rounding_of_the_state_add_up"
    "[dual pairs BLAS]",
    "tests/test_threads.py::test_compiled_members_calling_blas_run_serially_under_blas_threads",
    "tests/test_semidirect.py::test_compiled_pairs_equal_the_numpy_path[u3]",
    "tests/test_semidirect.py::test_a_hopeless_pair_step_freezes_that_member_on_the_compiled_path",
    "tests/test_compiled.py::test_ensemble_member_that_fails_is_frozen_like_numpy[",
    *(
        f"tests/test_compiled.py::test_compiled_equals_numpy[{c}]"
        for c in (
            "CompiledB su(34) BLAS",
            "CompiledB spin chain (generic particles)",
            "CompiledB (R^3, x)^6",
            "CompiledB (R^3, x)^6 spherical",
            "herm(33) BLAS",
            "su(40) BLAS",
            "u(70) BLAS, a short last row block",
        )
    ),
    "tests/test_compiled.py::test_chunks_give_the_same_run_bit_for_bit[CompiledB (R^3, x)^6 sph",
    "tests/test_compiled.py::test_compiled_compositions_equal_numpy[u(40) BLAS, kahan-li-6]",
    "tests/test_compiled.py::test_planar_3m_stage_equals_numpy_and_the_complex_tiles[",
    "tests/test_noise_spins.py::test_one_spin_in_a_field_follows_the_langevin_function[0.5]",
    "tests/test_noise_spins.py::test_thermal_lattice_matches_metropolis_monte_carlo[0.5]",
    "tests/test_noise_spins.py::test_thermal_lattice_matches_metropolis_monte_carlo[2.0]",
    *(
        f"tests/test_conformance.py::test_a_method_written_once_runs_compiled_on_every_layout[{c}]"
        for c in (
            "dense, SIMD lanes",
            "dual pairs, written-out products",
            "heavy top",
            "dense, BLAS",
            "dual pairs, BLAS",
            "vortices on the sphere",
            "vortices on the hyperboloid",
            "(R^3, x)^N",
            "(R^3, x_L)^N",
            "spin chain",
        )
    ),
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.nodeid.startswith(SLOW):
            item.add_marker(pytest.mark.slow)


@pytest.fixture
def rng():
    import numpy as np

    return np.random.default_rng(12345)
