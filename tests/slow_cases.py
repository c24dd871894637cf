# ruff: noqa: E501  (test ids are quoted whole, so that searching for one finds it)
"""Which tests the README's test command leaves out, and why: ``pytest -m slow`` runs them, and
CI runs both.

The default run is sized for a newcomer: about four minutes from a fresh clone on two cores,
numba compiling everything it runs. Where its time went was measured with a recorder of the
compiled loops each test runs (driver signatures: layout x stage x field x dtype, serial or
parallel), cold and warm, from a fresh clone on the idle machine (2026-11-26): 840
worker-seconds cold, 377 warm; each loop compiles for 7-30 s the first time a run needs it.
Three groups are left out:

:data:`LONG`
    Picked by hand: long runs (10^4-10^5 steps, the experiments), fresh processes compiling on
    new caches, and the first case of a compiled family that paid its compilation.
:data:`OWN_LOOP`
    Cases whose compiled loop no default case runs. The default run compiles the loops of
    twelve combinations, one or two per layout family: the small dense spaces (so(n) real,
    herm(n) in a frame and su(N) complex, a user's ``CompiledB`` so(8)), the spin chain, the
    vortices on the sphere and on the hyperboloid, the heavy top and the dual pairs, the
    ``(R^3, x)^N`` particles, the complex BLAS tiles (Euler on the sphere) and the sphere's
    split step. These cases are the only default users of the noise's stochastic stages, the
    QG model's loops, the member lanes and blocks, the real BLAS layout and the threaded
    ensembles; the properties they check are checked on those loops only by the slow run.
:data:`OVER_A_SECOND`
    Cases that took over a second each on a warm cache (the time is beside each), except
    the guarantees a newcomer should see pass at once (:data:`KEPT`): a SIGKILLed su(N) run
    resumes bit for bit, a kill at any write leaves a file that resumes, the demo reports
    rounding-level drift, thread limits bound every request, a changed user model is not
    resumed, a sweep's members equal serial solves.

``conftest.py`` marks them and, when the whole suite is collected, fails on an entry that names
no test (a renamed test must not drop out of both runs silently).
"""

from __future__ import annotations

#: Long checks, picked by hand (cases of a parametrization by their ids, and whole modules).
#: Each took over a minute in a full run on the loaded 2-core machine (about 10-40 s quiet).
#: Each property they check keeps a fast case in the default run where one exists (one layout of
#: the toy method, one compiled case per layout family, the experiments' figures).
LONG = (
    "tests/test_experiments.py::",
    # two fresh processes compiling every fused loop that moves a state on a new cache (2 min)
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
    "tests/test_noise.py::test_the_chains_threaded_stochastic_sweeps_equal_the_serial_ones",
    "tests/test_noise.py::test_the_damped_chain_runs_on_the_fused_sweeps_as_on_the_generic_stage",
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

#: The only default users of their compiled loop (measured, 2026-11-26; see the module).
OWN_LOOP = (
    # the stochastic stages, drawn ahead or together: loops of the noise only the slow run compiles
    "tests/test_draws_ahead.py::test_pieces_give_the_undivided_run_bit_for_bit",
    "tests/test_draws_ahead.py::test_an_ensemble_drawn_together_gives_the_run_drawn_inline_bit_for_bit",
    "tests/test_draws_ahead.py::test_a_run_whose_writer_works_beside_its_loop_draws_inline",
    "tests/test_draws_ahead.py::test_a_member_that_fails_inside_a_piece_fails_as_in_the_undivided_run",
    "tests/test_draws_ahead.py::test_a_field_that_raises_inside_a_piece_fails_as_in_the_undivided_run",
    "tests/test_draws_ahead.py::test_an_error_while_drawing_a_later_piece_reaches_the_caller",
    "tests/test_budget_files.py::test_budgets_and_spectra_are_saved_per_save_and_read_back[qg]",
    "tests/test_budget_files.py::test_plot_draws_the_budgets_spectra_and_zonal_wind",
    "tests/test_compensated.py::test_increments_below_the_rounding_of_the_state_add_up[dense BLAS]",
    "tests/test_compensated.py::test_increments_below_the_rounding_of_the_state_add_up[lanes]",
    "tests/test_compiled.py::test_blocked_ensemble_member_failure_matches_numpy",
    "tests/test_compiled.py::test_chunks_give_the_same_run_bit_for_bit[so(40) BLAS]",
    "tests/test_compiled.py::test_compiled_compositions_equal_numpy[rigid ensemble 20, triple-jump]",
    "tests/test_compiled.py::test_compiled_equals_numpy[so(130) BLAS, triangular blocks]",
    "tests/test_compiled.py::test_compiled_equals_numpy[so(40) BLAS ensemble 3]",
    "tests/test_compiled.py::test_compiled_equals_numpy[so(40) BLAS]",
    "tests/test_compiled.py::test_user_function_that_raises_fails_the_run_with_it_as_cause",
    "tests/test_docs_snippets.py::test_docstring_examples_run[isoflow.ensemble]",
    "tests/test_docs_snippets.py::test_docstring_examples_run[isoflow.methods.stochastic_isomp]",
    "tests/test_docs_snippets.py::test_documentation_page_runs[docs/user_guide/sweeps.rst]",
    "tests/test_leaving_the_space.py::test_a_file_holds_only_states_in_the_space",
    "tests/test_leaving_the_space.py::test_one_system_that_leaves_the_space_fails[compiled]",
    "tests/test_leaving_the_space.py::test_only_the_member_that_leaves_fails[compiled]",
    "tests/test_model_rigid_body.py::test_ensemble_equals_separate_runs[fixed]",
    "tests/test_model_toda.py::test_ensemble_equals_separate_runs[fixed]",
    "tests/test_noise.py::test_compiled_and_numpy_paths_take_the_same_noisy_steps_and_keep_the_casimirs",
    "tests/test_noise.py::test_ensemble_statistics_are_the_members_sample_moments_without_the_failed",
    "tests/test_noise.py::test_member_ids_key_the_paths_whatever_the_ensemble_and_the_threads",
    "tests/test_noise.py::test_zero_noise_is_isomp_from_the_state_bit_for_bit",
    "tests/test_noise_orders.py::test_stochastic_heun_has_strong_order_one_half_and_drifts_off_the_casimirs",
    "tests/test_noise_runs.py::test_the_tasks_of_a_sweep_draw_what_one_ensemble_of_its_members_draws",
    "tests/test_noise_spins.py::test_gilbert_damping_is_the_llg_double_bracket_with_its_sign",
    "tests/test_noise_spins.py::test_one_spin_in_a_field_follows_the_langevin_function[2.0]",
    "tests/test_noise_spins.py::test_thermal_lattice_matches_metropolis_monte_carlo[1.0]",
    "tests/test_qg.py::test_F_zero_is_euler_bit_for_bit_and_small_F_tends_to_it",
    "tests/test_qg.py::test_casimirs_of_the_potential_vorticity_at_rounding_and_energy_bounded",
    "tests/test_qg.py::test_helmholtz_rossby_waves_travel_at_2_omega_over_lambda_plus_kappa2",
    "tests/test_qg.py::test_qg_drag_relaxes_to_rest_not_to_zero_potential_vorticity",
    "tests/test_qg.py::test_qg_energy_budget_closes_with_dissipation_and_forcing",
    "tests/test_raising_members.py::test_only_the_member_whose_b_raises_fails[compiled, parallel]",
    "tests/test_raising_members.py::test_only_the_member_whose_b_raises_fails[compiled, serial]",
    "tests/test_raising_members.py::test_throw_raises_with_the_exception_as_cause[compiled, parallel]",
    "tests/test_raising_members.py::test_throw_raises_with_the_exception_as_cause[compiled, serial]",
    "tests/test_restart_layouts.py::test_a_kill_at_any_write_resumes_bit_for_bit[so(4) composition ensemble]",
    "tests/test_spin_lattice.py::test_ensemble_and_bad_parameters",
    "tests/test_sweep.py::test_a_member_whose_compiled_b_raises_fails_alone",
    "tests/test_threads.py::test_a_number_of_cores_goes_to_the_pool_the_run_uses",
    "tests/test_threads.py::test_the_threads_used_are_in_the_stats_the_file_and_isoflow_info",
    # the Cayley update on the small dense layouts and their lanes, on particles and the chain's
    # sweeps, and the stochastic stages with it or on the BLAS layout (2026-11-27: 106 tests of
    # these four files took 258 s cold on one process, about 80 s of the default run's time)
    "tests/test_stochastic_cayley.py::test_every_paths_spectrum_stays_at_rounding_whatever_the_tolerance",
    "tests/test_stochastic_cayley.py::test_at_a_tight_tolerance_it_is_the_midpoint_update",
    "tests/test_stochastic_cayley.py::test_the_compiled_finish_is_the_numpy_one",
    "tests/test_stochastic_cayley.py::test_each_member_of_an_ensemble_takes_its_own_path",
    "tests/test_stochastic_cayley.py::test_the_default_solver_and_the_name_follow_the_update",
    "tests/test_stochastic_cayley.py::test_thermal_spins_keep_every_length_whatever_the_tolerance",
    "tests/test_stochastic_cayley.py::test_an_ensemble_of_small_members_runs_it_on_the_lanes",
    "tests/test_cayley_update.py::test_particles_keep_every_length_whatever_the_tolerance",
    "tests/test_cayley_update.py::test_the_small_dense_finish_is_the_numpy_one",
    "tests/test_cayley_update.py::test_the_written_out_inverse_holds_at_any_step[so(6)]",
    "tests/test_cayley_update.py::test_the_written_out_inverse_holds_at_any_step[u(5)]",
    "tests/test_noise.py::test_the_noise_term_formed_once_a_step_is_the_numpy_paths",
    "tests/test_noise.py::test_the_blas_iterations_with_noise_take_the_numpy_paths_steps",
    "tests/test_restart_layouts.py::test_a_kill_at_any_write_resumes_bit_for_bit[su(17) BLAS, stochastic Cayley update]",
    "tests/test_restart_layouts.py::test_a_kill_at_any_write_resumes_bit_for_bit[spin chain (fused), Cayley update]",
    "tests/test_restart_layouts.py::test_a_kill_at_any_write_resumes_bit_for_bit[(R^3,x)^N thermal particles, stochastic Cayley update]",
    "tests/test_restart_layouts.py::test_a_kill_at_any_write_resumes_bit_for_bit[su(5) lanes ensemble, Cayley update]",
    "tests/test_restart_layouts.py::test_a_kill_at_any_write_resumes_bit_for_bit[so(5) dense, Cayley update]",
    # the u(512) loop with the dense start from the lower triangle (and the NumPy path at 512)
    "tests/test_dense_start.py::test_a_large_run_from_the_lower_triangle_keeps_its_states",
)

#: Over a second each on a warm cache (measured, 2026-11-26; see the module).
OVER_A_SECOND = (
    "tests/test_cli.py::test_user_mistakes_give_one_line_errors[args2-1-isoflow: error: .*not a whole number of steps]",  # 1.0 s
    "tests/test_cli_app.py::test_a_closed_pipe_is_not_an_error",  # 1.2 s
    "tests/test_cli_app.py::test_bench_mistakes_are_one_line_errors[",  # 1.2 s each
    "tests/test_cli_app.py::test_bench_runs_a_benchmark_of_the_suite",  # 3.4 s
    "tests/test_cli_app.py::test_plot_does_not_replace_files_silently",  # 5.7 s
    "tests/test_cli_run.py::test_run_from_toml_matches_options",  # 3.3 s
    "tests/test_cli_run.py::test_run_info_plot",  # 4.5 s
    "tests/test_cli_run.py::test_user_mistakes[args0-1-unknown model 'pendulum']",  # 1.8 s
    "tests/test_compensated.py::test_brouwer_law_over_a_million_steps",  # 2.2 s
    "tests/test_compensated.py::test_increments_below_the_rounding_of_the_state_add_up[su(N) BLAS real planes]",  # 5.2 s
    "tests/test_compile_clock.py::test_a_new_kernel_is_announced_on_stderr_and_counted_then_loaded_silently",  # 3.7 s
    "tests/test_compile_clock.py::test_the_command_line_announces_also_with_quiet",  # 1.3 s
    "tests/test_compile_clock.py::test_the_notice_comes_from_python_too_unless_progress_is_off[False]",  # 1.7 s
    "tests/test_compile_clock.py::test_the_notice_comes_from_python_too_unless_progress_is_off[None]",  # 6.1 s
    "tests/test_composition.py::test_ensemble_equals_separate_runs",  # 1.2 s
    "tests/test_composition.py::test_one_warm_start_per_substep_position",  # 1.2 s
    "tests/test_composition.py::test_spectrum_preserved_over_many_steps_matrices[herm3]",  # 1.4 s
    "tests/test_composition.py::test_spectrum_preserved_over_many_steps_matrices[u3]",  # 1.2 s
    "tests/test_conformance.py::test_structure[IsoMP o suzuki-4 on se3-vectors]",  # 2.0 s
    "tests/test_conformance.py::test_structure[IsoMP o suzuki-4 on sl2-vectors]",  # 1.4 s
    "tests/test_conformance.py::test_structure[IsoMP o suzuki-4 on su3-pairs]",  # 1.3 s
    "tests/test_conformance.py::test_structure[IsoMP, Newton on glC3]",  # 1.1 s
    "tests/test_conformance.py::test_structure[IsoMP, Newton on se3-vectors]",  # 1.2 s
    "tests/test_conformance.py::test_structure[IsoMP, Newton on su3-pairs]",  # 1.6 s
    "tests/test_euler_sphere.py::test_casimirs_at_rounding_over_many_steps[32-0.0-0.1-10000]",  # 5.8 s
    "tests/test_faults.py::test_a_full_disk_stops_the_run_cleanly_and_the_file_resumes",  # 6.2 s
    "tests/test_faults.py::test_a_full_disk_through_the_cli",  # 5.0 s
    "tests/test_faults.py::test_a_second_writer_gets_a_clear_error",  # 6.9 s
    "tests/test_faults.py::test_output_replaced_only_if_it_is_a_regular_file",  # 1.5 s
    "tests/test_faults.py::test_signals_at_random_moments[",  # 11.8 s and 4.8 s
    "tests/test_faults.py::test_writes_failing_after_k_bytes_stop_the_run_and_resume[28]",  # 1.9 s
    "tests/test_faults.py::test_writes_failing_after_k_bytes_stop_the_run_and_resume[5]",  # 1.0 s
    "tests/test_heavy_top.py::test_the_fourth_integral_is_conserved_by_the_exact_flow[kovalevskaya]",  # 2.1 s
    "tests/test_heavy_top.py::test_the_fourth_integral_is_conserved_by_the_exact_flow[lagrange]",  # 3.3 s
    "tests/test_io.py::test_streaming_memory_does_not_grow_with_the_number_of_steps",  # 5.7 s
    "tests/test_isomp.py::test_isospectral_in_space_over_1000_steps[sl2-linear]",  # 1.1 s
    "tests/test_isomp.py::test_isospectral_in_space_over_1000_steps[sl2-nonlinear]",  # 1.1 s
    "tests/test_isomp.py::test_isospectral_in_space_over_1000_steps[sp4-linear]",  # 1.2 s
    "tests/test_isomp.py::test_isospectral_in_space_over_1000_steps[sp4-nonlinear]",  # 1.7 s
    "tests/test_isosyrk.py::test_long_run_stays_in_the_space",  # 4.1 s
    "tests/test_layers.py::test_no_import_cycles",  # 1.1 s
    "tests/test_layers.py::test_no_package_is_callable_or_binds_a_submodule_name_lazily",  # 1.8 s
    "tests/test_mhd_sphere.py::test_a_kill_at_any_write_of_an_mhd_run_resumes_bit_for_bit",  # 1.4 s
    "tests/test_mhd_sphere.py::test_both_casimir_families_at_rounding_and_the_energy_bounded[16-0.0-0.1-5000]",  # 2.2 s
    "tests/test_mhd_sphere.py::test_run_info_plot_through_the_command_line",  # 1.5 s
    "tests/test_model_brockett.py::test_ensemble_equals_separate_runs[newton]",  # 1.9 s
    "tests/test_model_toda.py::test_ensemble_equals_separate_runs[newton]",  # 1.9 s
    "tests/test_model_toda.py::test_newton_matches_fixed_point[dense]",  # 1.1 s
    "tests/test_noise_runs.py::test_a_killed_stochastic_run_resumes_on_the_same_path_bit_for_bit",  # 8.8 s
    "tests/test_restart_layouts.py::test_a_kill_at_any_write_resumes_bit_for_bit[su(17) BLAS]",  # 1.2 s
    "tests/test_sphere.py::test_figures_are_labelled_figures",  # 3.8 s
    "tests/test_spherical_midpoint.py::test_conserves_every_per_particle_quadratic_invariant",  # 2.1 s
    "tests/test_spin_chain.py::test_classical_midpoint_runs_and_keeps_quadratic_invariants",  # 1.3 s
    "tests/test_sweep.py::test_every_member_equals_a_serial_solve[perturbed-rigid-body]",  # 3.4 s
    "tests/test_sweep.py::test_task_names_are_stable_across_processes_and_key_order",  # 1.3 s
    "tests/test_sweep.py::test_worker_killed_mid_task_is_retried_and_resumed",  # 5.3 s
    "tests/test_threads.py::test_limits_hold_inside_the_loop_for_numpys_and_scipys_openblas",  # 3.2 s
    "tests/test_threads.py::test_the_command_lines_default_takes_effect_against_the_libraries_default",  # 2.2 s
)

#: Over a second, kept in the default run on purpose (see the module).
KEPT = (
    "tests/test_restart_layouts.py::test_sigkill_of_an_su_n_run_then_resume_is_bit_for_bit",
    "tests/test_faults.py::test_a_kill_at_any_write_leaves_a_file_that_resumes",
    "tests/test_cli.py::test_demo_reports_rounding_level_casimir_drift",
    "tests/test_threads.py::test_environment_variables_bound_every_request",
    "tests/test_cli_user_model.py::test_resume_of_a_changed_user_model_is_refused_unless_forced",
    "tests/test_sweep.py::test_every_member_equals_a_serial_solve[toda]",
)

SLOW = LONG + OWN_LOOP + OVER_A_SECOND
