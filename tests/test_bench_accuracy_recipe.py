"""``sray bench accuracy``'s plan against the recipe: the headline cell (``hour-intra-uncapped``) trains
``synth-cpu-hour`` exactly as it is (settings, CPU budget and world), the other CPU-budgeted cells change one thing
each."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from sray.data_tools.synth.world import SHARDS
from sray.jobs.bench import accuracy_cells
from sray.jobs.bench.accuracy_plan import (CAPPED_STEPS, CPU_BUDGETED, HOUR, HOUR_CROSS, HOUR_INTRA,
                                           HOUR_INTRA_UNCAPPED, HOUR_INVERSE, HOUR_NONE, HOUR_TWICE,
                                           HOUR_SAMPLES_16, HOUR_WARM, LONG, PRESETS, RECIPE_ROOMS, RECIPE_VARIANT,
                                           ROOMS_198, ROOMS_498, SCREEN, SCREEN_DEPTH,
                                           SCREEN_LR_RAYS, SCREEN_NARROW_12, SCREEN_OCCL, SCREEN_OCCL_T5,
                                           SCREEN_RAYS_128, SCREEN_RAYS_512,
                                           SCREEN_LR_2X, SCREEN_ROOMS_998, SCREEN_SAMPLES_16,
                                           SCREEN_SECONDS, SCREEN_SRC_3, SCREEN_VIEWS_8, SCREEN_WARM, SCREEN_WARM_750,
                                           SCREEN_WIDE_24,
                                           VARIANT_SETTINGS, WARM_2D_STEPS,
                                           Cell, headline_variant, seeds)
from sray.jobs.bench.accuracy_worlds import WORLDS_DIR
from sray.platform.config.recipes import get_recipe


def test_the_headline_cell_is_the_recipe_with_its_cpu_budget_and_world_and_the_others_count_steps(
        tmp_path: Path) -> None:
    """``hour-intra-uncapped``, the headline, trains synth-cpu-hour as it is (settings, intra-only attention, 2D
    warm-up, CPU-second budget with a step cap beyond it, and the world its shards default to, which the benchmark
    generates in its default folder); ``hour-intra`` is the same capped at 5,000 steps, as every other CPU-budgeted
    cell, ``hour-warm2d`` that with full CRA, ``hour-498`` that without the warm-up and ``hour``, ``hour-198`` that
    on other worlds, so their stored cells stay valid; ``long`` keeps its fixed step budget and ablation cells their
    short one, both without a CPU budget; the occlusion, attention and depth-loss cells are ``hour-warm2d`` with one
    model setting changed, at the same CPU budget and world."""
    recipe, preset = get_recipe("synth-cpu-hour"), PRESETS["cpu-small"]
    assert headline_variant(preset) == RECIPE_VARIANT == HOUR_INTRA_UNCAPPED
    assert VARIANT_SETTINGS[HOUR_INTRA_UNCAPPED].train_scenes == RECIPE_ROOMS
    assert recipe.optim.warmup_2d_steps == WARM_2D_STEPS > 0
    default_out = Path("outputs/bench-accuracy/cpu-small")  # `sray bench accuracy`'s folder for the preset
    assert Path(recipe.data.shards) == default_out / WORLDS_DIR / f"train{RECIPE_ROOMS}" / SHARDS
    recipe_cell = accuracy_cells.cell_config(Cell(HOUR_INTRA_UNCAPPED, 1), preset, tmp_path / "shards", tmp_path,
                                             "sqlite:///x.db")
    assert recipe_cell.model == recipe.model and recipe_cell.optim == recipe.optim and recipe_cell.run.seed == 1
    head = accuracy_cells.cell_config(Cell(HOUR_INTRA, 1), preset, tmp_path / "shards", tmp_path, "sqlite:///x.db")
    capped = dataclasses.replace(recipe.optim, steps=CAPPED_STEPS)  # the other cells' cap, below the recipe's
    assert dataclasses.replace(head, run=recipe_cell.run) == dataclasses.replace(recipe_cell, optim=capped)
    assert CAPPED_STEPS < recipe.optim.steps and head.run.ckpt_every == recipe_cell.run.ckpt_every
    full_cra = dataclasses.replace(recipe.model, attention="full")
    warm = accuracy_cells.cell_config(Cell(HOUR_WARM, 1), preset, tmp_path / "shards", tmp_path, "sqlite:///x.db")
    assert dataclasses.replace(warm, run=head.run) == dataclasses.replace(head, model=full_cra)
    assert dataclasses.replace(head.data, shards=recipe.data.shards) == recipe.data
    assert head.optim.cpu_seconds > 0 and head.run.val_every == recipe.run.val_every
    long = accuracy_cells.cell_config(Cell(LONG, 0), preset, tmp_path / "shards", tmp_path, "sqlite:///x.db")
    assert (long.optim.steps, long.optim.cpu_seconds, long.run.val_every) == (2500, 0.0, 2500 // preset.validations)
    assert long.model.fine_samples == "union" and long.model.lambda_src_sem == 0.0 and long.data.visit_samples == 16
    assert long.optim.warmup_2d_steps == 0
    for variant in VARIANT_SETTINGS.keys() - {*CPU_BUDGETED, LONG}:
        cfg = accuracy_cells.cell_config(Cell(variant, 0), preset, tmp_path / "shards", tmp_path, "sqlite:///x.db")
        assert (cfg.optim.steps, cfg.optim.cpu_seconds) == (preset.ablation_steps, 0.0), variant
        assert cfg.optim.warmup_2d_steps == VARIANT_SETTINGS[variant].warmup_2d_steps, variant
    unwarmed = dataclasses.replace(head.optim, warmup_2d_steps=0)
    for variant, rooms in ((HOUR, None), (ROOMS_198, 198), (ROOMS_498, RECIPE_ROOMS)):  # the recipe before its warm-up
        cfg = accuracy_cells.cell_config(Cell(variant, 1), preset, tmp_path / "shards", tmp_path, "sqlite:///x.db")
        assert dataclasses.replace(cfg, run=head.run) == dataclasses.replace(head, optim=unwarmed, model=full_cra)
        assert cfg.run.name == f"bench-{variant}-s1"
        assert VARIANT_SETTINGS[variant] == dataclasses.replace(VARIANT_SETTINGS[HOUR_WARM], train_scenes=rooms,
                                                                warmup_2d_steps=0)
    one_lever = ((HOUR_NONE, {"attention": "none"}), (HOUR_CROSS, {"attention": "cross"}),
                 (HOUR_INTRA, {"attention": "intra"}))
    for variant, change in one_lever:  # hour-warm2d with one model setting changed, at the same CPU budget
        cfg = accuracy_cells.cell_config(Cell(variant, 1), preset, tmp_path / "shards", tmp_path, "sqlite:///x.db")
        assert cfg.model == dataclasses.replace(full_cra, **change), variant
        assert dataclasses.replace(cfg, run=head.run, model=head.model) == head
        assert cfg.run.name == f"bench-{variant}-s1" and VARIANT_SETTINGS[variant].train_scenes == RECIPE_ROOMS
    assert recipe.model.attention == "intra"
    planned = [c.variant for c in preset.plan]
    after = planned[planned.index(ROOMS_498):][:10]
    assert after == [*[ROOMS_498] * 3, *[HOUR_WARM] * 3, *[HOUR_NONE] * 3, HOUR_CROSS]


def test_the_screening_cells_are_the_recipe_at_half_its_budget_with_one_change_each(tmp_path: Path) -> None:
    """``screen`` trains synth-cpu-hour exactly as it is but for its CPU budget (``SCREEN_SECONDS``, half the
    recipe's); ``screen-warm3k`` doubles its 2D warm-up, ``screen-depth`` / ``screen-occl`` / ``screen-occl-t5``
    change one model setting each, ``screen-rays128`` the query rays per step, ``screen-samples16`` the samples
    per ray, ``screen-998`` the training rooms (998, a world with the same test rooms) and ``screen-lr-rays`` where
    the lr decay starts. All are planned, paired on seed 0; the occlusion lever, the two step-cost levers, the rooms
    and the lr lever and their baseline on seeds 0-2, with no hour arm for the occlusion, the rays or the rooms lever
    (none clear of the seed spread over those seeds, docs/benchmarks.md); the lr lever's hour arm, ``hour-lr-rays``,
    is the recipe with the same decay start, on seed 0 (its loss there ended the lever); the samples lever's,
    ``hour-samples16``, is the recipe with 16+16 samples per ray, on seeds 0-2 (it gained on all three screened);
    ``hour-2x`` is the recipe at twice its CPU budget, on seeds 0-2."""
    recipe, preset = get_recipe("synth-cpu-hour"), PRESETS["cpu-small"]
    assert SCREEN_SECONDS == recipe.optim.cpu_seconds / 2

    def config(variant: str):
        return accuracy_cells.cell_config(Cell(variant, 0), preset, tmp_path / "shards", tmp_path, "sqlite:///x.db")

    head, screen, warm = config(HOUR_INTRA_UNCAPPED), config(SCREEN), config(SCREEN_WARM)
    assert dataclasses.replace(screen, run=head.run) == dataclasses.replace(
        head, optim=dataclasses.replace(recipe.optim, cpu_seconds=SCREEN_SECONDS))
    assert dataclasses.replace(warm, run=screen.run) == dataclasses.replace(
        screen, optim=dataclasses.replace(screen.optim, warmup_2d_steps=2 * WARM_2D_STEPS))
    one_lever = ((SCREEN_DEPTH, {"lambda_depth": 0.1}),)
    for variant, change in one_lever:  # the screening baseline with one model setting changed, at its budget
        cfg = config(variant)
        assert cfg.model == dataclasses.replace(screen.model, **change), variant
        assert dataclasses.replace(cfg, run=screen.run, model=screen.model) == screen, variant
    rays = config(SCREEN_RAYS_128)  # a step-cost lever: the screening baseline but for its query rays per step
    assert rays.data.rays_per_batch == 128 != screen.data.rays_per_batch
    assert dataclasses.replace(rays, run=screen.run, data=screen.data) == screen
    assert dataclasses.replace(rays.data, rays_per_batch=screen.data.rays_per_batch) == screen.data
    more_rays = config(SCREEN_RAYS_512)  # its other side: twice the query rays per step, nothing else changed
    assert more_rays.data.rays_per_batch == 512 and SCREEN_RAYS_512 in CPU_BUDGETED
    assert [c for c in preset.plan if c.variant == SCREEN_RAYS_512] == [Cell(SCREEN_RAYS_512, 2)]  # its one pair lost
    assert dataclasses.replace(more_rays, data=dataclasses.replace(more_rays.data, rays_per_batch=256),
                               run=screen.run) == screen
    samples = config(SCREEN_SAMPLES_16)  # the other step-cost lever: 16+16 samples per ray instead of 24+24
    assert (samples.model.n_coarse, samples.model.n_fine) == (16, 16) != (screen.model.n_coarse, screen.model.n_fine)
    unchanged = dataclasses.replace(samples.model, n_coarse=screen.model.n_coarse, n_fine=screen.model.n_fine)
    assert unchanged == screen.model
    assert dataclasses.replace(samples, run=screen.run, model=screen.model) == screen
    rooms = VARIANT_SETTINGS[SCREEN_ROOMS_998]  # the rooms lever: the same training on a larger world
    assert rooms == dataclasses.replace(VARIANT_SETTINGS[SCREEN], train_scenes=998)
    assert (998 - preset.world.train_scenes) % 5 == 0  # the generator's 5 room types: the test rooms stay the same
    assert dataclasses.replace(config(SCREEN_ROOMS_998), run=screen.run) == screen
    hour_samples = config(HOUR_SAMPLES_16)  # the samples lever's hour arm: the recipe exactly, but for 16+16 samples
    assert (hour_samples.model.n_coarse, hour_samples.model.n_fine) == (16, 16) != (head.model.n_coarse,
                                                                                   head.model.n_fine)
    assert dataclasses.replace(hour_samples, run=head.run, model=dataclasses.replace(
        hour_samples.model, n_coarse=head.model.n_coarse, n_fine=head.model.n_fine)) == head
    assert Cell(HOUR_SAMPLES_16, 0) in preset.plan and HOUR_SAMPLES_16 in CPU_BUDGETED
    inverse = config(HOUR_INVERSE)  # the class-weight lever: the recipe exactly, but for inverse-frequency weights
    assert (head.data.class_balance, inverse.data.class_balance) == ("inverse-sqrt", "inverse")
    assert dataclasses.replace(inverse, run=head.run, data=dataclasses.replace(inverse.data,
                                                                               class_balance="inverse-sqrt")) == head
    assert Cell(HOUR_INVERSE, 0) in preset.plan and HOUR_INVERSE in CPU_BUDGETED
    wide = config(SCREEN_WIDE_24)  # the capacity lever: a wider encoder, its 2D warm-up cut to the same CPU
    assert (wide.model.encoder_width, wide.optim.warmup_2d_steps) == (24, 680) != (16, screen.optim.warmup_2d_steps)
    assert dataclasses.replace(wide, run=screen.run, model=dataclasses.replace(wide.model, encoder_width=16),
                               optim=dataclasses.replace(wide.optim, warmup_2d_steps=WARM_2D_STEPS)) == screen
    assert [c for c in preset.plan if c.variant == SCREEN_WIDE_24] == [Cell(SCREEN_WIDE_24, 2)]
    assert SCREEN_WIDE_24 in CPU_BUDGETED
    narrow = config(SCREEN_NARROW_12)  # its other side: a narrower encoder, its 2D warm-up lengthened to the same CPU
    assert (narrow.model.encoder_width, narrow.optim.warmup_2d_steps) == (12, 1875)
    assert dataclasses.replace(narrow, run=screen.run, model=dataclasses.replace(narrow.model, encoder_width=16),
                               optim=dataclasses.replace(narrow.optim, warmup_2d_steps=WARM_2D_STEPS)) == screen
    assert [c for c in preset.plan if c.variant == SCREEN_NARROW_12] == [Cell(SCREEN_NARROW_12, 2),
                                                                         Cell(SCREEN_NARROW_12, 0)]
    assert SCREEN_NARROW_12 in CPU_BUDGETED
    heavier = config(SCREEN_SRC_3)  # the source-view loss weighted 3 instead of 1, nothing else changed
    assert (screen.model.lambda_src_sem, heavier.model.lambda_src_sem) == (1.0, 3.0)
    assert dataclasses.replace(heavier, run=screen.run, model=dataclasses.replace(heavier.model, lambda_src_sem=1.0)) \
        == screen
    assert [c for c in preset.plan if c.variant == SCREEN_SRC_3] == [Cell(SCREEN_SRC_3, 2), Cell(SCREEN_SRC_3, 0)]
    assert SCREEN_SRC_3 in CPU_BUDGETED
    doubled = config(SCREEN_LR_2X)  # the whole lr schedule twice as high, nothing else changed
    assert (screen.optim.lr, screen.optim.lr_final) == (1e-3, 1e-4)
    assert (doubled.optim.lr, doubled.optim.lr_final) == (2e-3, 2e-4)
    assert dataclasses.replace(doubled, run=screen.run, optim=dataclasses.replace(doubled.optim, lr=1e-3,
                                                                                  lr_final=1e-4)) == screen
    assert [c for c in preset.plan if c.variant == SCREEN_LR_2X] == [Cell(SCREEN_LR_2X, 0)]
    assert SCREEN_LR_2X in CPU_BUDGETED
    shorter = config(SCREEN_WARM_750)  # the 2D warm-up halved, nothing else changed
    assert (screen.optim.warmup_2d_steps, shorter.optim.warmup_2d_steps) == (1500, 750)
    assert dataclasses.replace(shorter, run=screen.run,
                               optim=dataclasses.replace(shorter.optim, warmup_2d_steps=1500)) == screen
    assert [c for c in preset.plan if c.variant == SCREEN_WARM_750] == [Cell(SCREEN_WARM_750, 0)]
    assert SCREEN_WARM_750 in CPU_BUDGETED
    viewed = config(SCREEN_VIEWS_8)  # every training sample gets all 8 source views, nothing else changed
    assert (screen.data.aug.min_source, viewed.data.aug.min_source) == (2, 0)
    assert viewed.model.n_source == 8 and viewed.data.top_k == 12
    assert dataclasses.replace(viewed, run=screen.run, data=dataclasses.replace(
        viewed.data, aug=dataclasses.replace(viewed.data.aug, min_source=2))) == screen
    assert [c for c in preset.plan if c.variant == SCREEN_VIEWS_8] == list(seeds(SCREEN_VIEWS_8, 3))
    assert SCREEN_VIEWS_8 in CPU_BUDGETED
    twice = config(HOUR_TWICE)  # the recipe at twice its CPU budget, nothing else changed
    assert twice.optim.cpu_seconds == 2 * recipe.optim.cpu_seconds == 2 * head.optim.cpu_seconds
    assert dataclasses.replace(twice, run=head.run, optim=dataclasses.replace(
        twice.optim, cpu_seconds=recipe.optim.cpu_seconds)) == head
    assert [c for c in preset.plan if c.variant == HOUR_TWICE] == list(seeds(HOUR_TWICE, 3))
    assert HOUR_TWICE in CPU_BUDGETED
    assert recipe.model.tau == 0.7 and recipe.model.lambda_depth == 0.0
    screening = (SCREEN, SCREEN_WARM, SCREEN_DEPTH, SCREEN_OCCL, SCREEN_OCCL_T5, SCREEN_RAYS_128, SCREEN_SAMPLES_16,
                 SCREEN_ROOMS_998, SCREEN_LR_RAYS)
    assert set(screening) <= set(CPU_BUDGETED)
    assert {Cell(v, 0) for v in screening} <= set(preset.plan)
    assert {*seeds(SCREEN_OCCL, 3), *seeds(SCREEN, 3), *seeds(SCREEN_RAYS_128, 3),
            *seeds(SCREEN_SAMPLES_16, 3), *seeds(SCREEN_ROOMS_998, 3), *seeds(SCREEN_LR_RAYS, 3)} <= set(preset.plan)
