"""Names of the one-lever variants of ``sray lab accuracy``: each is the screening baseline ``screen`` or the recipe
(``hour-intra-uncapped``) with one setting changed, measured against it on paired seeds (their settings and cells:
:mod:`sray.lab.accuracy.plan`)."""

from __future__ import annotations

SCREEN_DEPTH, SCREEN_OCCL, SCREEN_OCCL_T5 = "screen-depth", "screen-occl", "screen-occl-t5"
"""Variant names of ``screen`` with one model setting changed each, screened against it at the same budget: the
training-time depth loss on the rendered depth (``model.lambda_depth`` 0.1; the test protocol stays
RGB), and the occlusion-aware weight net inputs (``model.weight_inputs=cross-view``) at the model's tau (0.7) and at
tau 0.5 (a wider weight range)."""

SCREEN_RAYS_128 = "screen-rays128"
"""Variant name of ``screen`` rendering 128 query rays per rank-step instead of 256 (``data.rays_per_batch``; a
step-cost lever: its ray step costs 0.79x the recipe's in ``sray lab recipe-step``, each with half the labels)."""

SCREEN_RAYS_512 = "screen-rays512"
"""Variant name of ``screen`` rendering 512 query rays per rank-step instead of 256 (``data.rays_per_batch``): the
other side of ``screen-rays128`` (half the labels per step for more steps: +3.70 ± 5.78 points zero-shot over three
paired seeds, one of them lost), twice the labels per step for fewer steps. Planned on seed 2 only, paired with
``screen`` of that seed on one machine (why: docs/benchmarks.md, "Twice the query rays per step")."""

SCREEN_SAMPLES_16 = "screen-samples16"
"""Variant name of ``screen`` with 16 coarse and 16 fine samples per ray instead of 24 and 24 (``model.n_coarse``,
``model.n_fine``; a step-cost lever: 0.83x the recipe's ray-step CPU in ``sray lab recipe-step``, the same labels)."""

SCREEN_ROOMS_998, ROOMS_998 = "screen-998", 998
"""Variant name of ``screen`` on 998 training rooms instead of 498 (the same test rooms; generating them is not counted
in the budget), and that count: zero-shot rose with every room count measured (48 -> 198 -> 498, docs/benchmarks.md)."""

SCREEN_LR_RAYS = "screen-lr-rays"
"""Variant name of ``screen`` whose lr decay starts at the first ray step (``optim.lr_decay_start=rays``): the 2D
warm-up trains at the base lr and the ray phase decays over its own share of the budget, instead of starting at
~0.6x the hour's lr (the decay follows the spent budget share, docs/benchmarks.md)."""

HOUR_LR_RAYS = "hour-lr-rays"
"""Variant name of ``synth-cpu-hour`` exactly as it is (``hour-intra-uncapped``) but for its lr decay starting at the
first ray step: the hour arm of ``screen-lr-rays``, which gained over ``screen`` on each of its three paired seeds.
Planned on seed 0 only (why: docs/benchmarks.md, "The hour arm's seed-0 pair")."""

HOUR_SAMPLES_16 = "hour-samples16"
"""Variant name of ``synth-cpu-hour`` exactly as it is (``hour-intra-uncapped``) but for 16 coarse and 16 fine samples
per ray: the hour arm of ``screen-samples16``, which gained over ``screen`` on each of its three paired seeds
(docs/benchmarks.md, "Samples per ray, screened on the third and fourth machines"). Planned on seed 0 only (why:
docs/benchmarks.md, "The samples lever's hour arm, seed 0")."""

HOUR_INVERSE = "hour-inverse"
"""Variant name of ``synth-cpu-hour`` exactly as it is (``hour-intra-uncapped``) but for its class weights following
the inverse class frequency instead of its square root (``data.class_balance=inverse``), both clipped at 10x the
smallest weight. On the 498-room world the clip flattens every class under 4.3% of the pixels, so the lever moves
weight from wall and floor (63% of the pixels) to the objects that hold mIoU down: wall 0.23, floor 0.50, cabinet
1.52, door 2.26 and every other class 2.33, against the recipe's 0.43, 0.63, 1.10, 1.35 and 1.53-4.32. It goes
to the hour without a screen: the two levers that gained at the screening budget on every seed (``screen-lr-rays``,
``screen-samples16``) did not at the hour (docs/benchmarks.md, "The samples lever's hour arm"). Planned on seed 0
only, paired with the recipe's seed 0 on one machine (why: docs/benchmarks.md, "Inverse-frequency class weights at
the hour")."""

SCREEN_WIDE_24, WIDE_24_WARMUP_2D = "screen-w24", 680
"""Variant name of ``screen`` with an encoder 24 channels wide at its first layer instead of 16
(``model.encoder_width``: 2.25x its parameters, 2.21x its multiply-adds on a 120x160 image), and its 2D warm-up's
steps, cut from 1,500 so the warm-up spends about the same CPU (1,500 / 2.21; a 2D step is almost all encoder). The
capacity lever: on the recipe's world, held-out views of the training rooms score no higher than unseen rooms, and
no lever that changed what a step trains on (rays, samples, weights, rooms, lr) raised held-out fitting at the hour.
Planned on seed 2 only, paired with ``screen`` of that seed on one machine; that pair lost (docs/benchmarks.md, "A
wider encoder, screened on seed 2")."""

SCREEN_NARROW_12, NARROW_12_WARMUP_2D = "screen-w12", 1875
"""Variant name of ``screen`` with an encoder 12 channels wide at its first layer instead of 16
(``model.encoder_width``: 0.56x its parameters), and its 2D warm-up's steps, raised from 1,500 so the warm-up spends
about the same CPU: its 2D step costs 0.80x the recipe's and its ray step 0.90x in ``sray lab recipe-step`` (tables
in docs/benchmarks.md, "Recipe step"). The other side of ``screen-w24``: whether a smaller encoder, with more steps
in the same CPU seconds, fits and transfers as well (in the two-rank cells its ray step cost 1.02x the recipe's, so
it made no more ray steps: the all-reduce, loaders and Ray do not shrink with it). Planned on seeds 2 and 0, each
paired with ``screen`` of that seed on one machine: seed 2 gained, seed 0 lost on both scores (docs/benchmarks.md, "A
narrower encoder")."""

SCREEN_SRC_3 = "screen-src3"
"""Variant name of ``screen`` with the source views' per-pixel semantic loss weighted 3 instead of 1
(``model.lambda_src_sem``): more of the encoder's gradient from the dense 2D labels during the ray phase, at no
extra step CPU. Measured because on the recipe's model that loss (class-weighted) still stands near 1.1 late in
training, above the ray semantic loss (about 0.9 per pass), and a linear probe reads less category information from
the encoder than S-Ray's render scores (the ceilings of docs/benchmarks.md), while longer 2D-only warm-ups and a
wider encoder, which buy 2D fitting with ray steps or CPU, lost. Planned on seeds 2 and 0, each paired with
``screen`` of that seed on one machine: seed 2 gained on both scores, seed 0 lost zero-shot, so the lever fails the
rule of a gain on every seed and the recipe keeps weight 1 (docs/benchmarks.md, "A heavier source-view loss")."""

SCREEN_RAY_BALANCE = "screen-raybal"
"""Variant name of ``screen`` whose query pixels favour each query image's small classes (``data.ray_balance=0.5``:
a pixel whose class covers n pixels of the image is drawn with probability proportional to n^-0.5), with the same
class-weighted loss. Why: on the recipe's model most of the held-out views' gap to the 60% target is in the classes
that only a few training rooms hold (desk, refrigerator, sink, counter, toilet: 10-44% IoU), and a uniform draw of
256 query pixels gives an object covering 2% of an image about 5 of them; the lever spends more of the same rays on
small objects at no extra step CPU. Planned on seed 0, paired with ``screen`` of that seed on one machine; that pair
did not gain (docs/benchmarks.md, "Class-balanced query pixels")."""

SCREEN_LR_2X = "screen-lr2x"
"""Variant name of ``screen`` whose whole learning-rate schedule is doubled (``optim.lr=2e-3``,
``optim.lr_final=2e-4``: the same linear warm-up and exponential decay, twice as high at every step). Why: at the
screening budget the ray phase gained on all three paired seeds when it started at the base lr instead of the decayed
one (``screen-lr-rays``: +4.25 ± 2.04 points zero-shot, +3.35 ± 1.49 held-out), a sign that the recipe's model is
still under-trained at its lr; doubling the base lr asks the same question of both phases at no extra step CPU.
Planned on seed 0, paired with ``screen`` of that seed on one machine: that pair lost 6.04 points zero-shot for 1.32
held-out, so the recipe keeps its lr (docs/benchmarks.md, "Twice the learning rate")."""

SCREEN_WARM_750 = "screen-warm750"
"""Variant name of ``screen`` whose 2D-only warm-up lasts 750 steps instead of 1,500 (``optim.warmup_2d_steps``): the
other side of ``screen-warm3k`` (twice the warm-up lost 2.71 points zero-shot and 5.00 held-out at this budget, the
ray steps it displaced being worth more than its 2D steps). Half the warm-up frees about 320 of the 3,600 CPU s for
ray steps (its seed-0 cell made 335 more than ``screen``'s, +15%); measured because held-out accuracy rises with ray
steps (+1.6 points per thousand over seven recipe cells) and the ceilings put the model's loss in recognition, which
both phases train. Planned on seed 0, paired with ``screen`` of that seed on one machine: that pair lost 2.45 points
zero-shot and 2.27 held-out, so the recipe keeps its 1,500 steps (docs/benchmarks.md, "Half the 2D warm-up")."""

SCREEN_GROUP_NORM = "screen-gn"
"""Variant name of ``screen`` whose encoder layers use group norm over groups of 8 channels instead of instance norm
(``model.encoder_norm=group``; the same parameters). Why: instance norm at every layer, down to the 8x10-pixel 1/16
stage and the 1/4 features the ray field reads, gives each channel of each image unit spread on its own, so a channel
that fires on a category keeps no trace of how much of the image holds it or of how it fires against its neighbours;
group norm keeps that within each group of 8 channels. Held-out views of the training rooms lose most in the furniture
that sets kitchens and offices apart (desk, refrigerator, sink, counter), where such context counts. Planned on seed 0,
paired with ``screen`` of that seed on one machine: that pair lost 3.58 points zero-shot and 1.10 held-out, and the
furniture it was aimed at did not rise, so the recipe keeps instance norm (docs/benchmarks.md, "Group-normalised
encoder layers")."""

SCREEN_WEIGHT_DECAY = "screen-wd"
"""Variant name of ``screen`` trained with AdamW's decoupled weight decay 0.3 on its convolution and linear weights
(``optim.weight_decay=0.3``; biases and norm scales do not decay). Why: every encoder convolution feeds an instance
norm, so its output ignores the scale of its weights; Adam's steps grow those weights, and a step of fixed size then
turns them less, so the encoder's effective learning rate falls as it trains, on top of the scheduled decay, in a
model that is still under-trained when its budget ends. Decay holds the weights' scale down and their effective rate
up. The screening schedule's learning rates sum to about 1.5 over its steps, so 0.3 would shrink a weight no gradient
touched to about 63% by the end: enough to matter in a run this short, where the usual 0.01-0.1 would not. Planned on
seeds 0-2, each paired with ``screen`` of that seed on one machine: the seed-0 pair gained 3.98 points zero-shot and
2.61 held-out with the encoder's weights ending 28% smaller and the training losses level, the seed-1 pair lost 2.45
and 0.77, the seed-2 pair gained 0.76 and lost 4.28: +0.76 ± 3.22 zero-shot and −0.81 ± 3.45 held-out over the three,
so the recipe keeps plain Adam (docs/benchmarks.md, "Decoupled weight decay")."""

SCREEN_WEIGHT_AVERAGE = "screen-ema"
"""Variant name of ``screen`` that keeps an exponential moving average of its weights with decay 0.998 (a horizon of
500 steps; ``optim.ema_decay=0.998``) and is scored, like every reader of its checkpoints, on the average. Why: each
rank-step's gradient comes from 256 query rays of one room and 8 source views, so the weights at the budget's end
carry the last few rooms' noise; an average over the last ~500 steps (about a quarter of the screening cell's ray
phase) spreads it over a few hundred rooms at no extra forward pass. Planned on seeds 0-2, each paired with
``screen`` of that seed on one machine: +0.79 ± 3.43 points zero-shot and −1.02 ± 3.55 held-out over the three, and
on the same checkpoints the average scored 0.82 zero-shot and 0.25 held-out below the live weights it averages (the
weights barely move once the learning rate has decayed, so the average only lags them), so the recipe keeps no
average (docs/benchmarks.md, "A moving average of the weights")."""

SCREEN_VIEWS_8 = "screen-views8"
"""Variant name of ``screen`` whose every training sample gets 8 source views (``data.aug.min_source=0``: 8 drawn
from the 12 nearest candidates) instead of 2 to 8 (5 on average, drawn from a random number of the nearest). Why:
evaluation always gives the model its 8 nearest views, so the recipe trains the weight network and the attention on
fewer views than it is scored on, and its encoder and source-view head see 5 labelled views per sample instead of 8;
the price is the encoding of those 3 extra views per sample, so fewer steps fit the budget. Planned on seeds 0-2,
each paired with ``screen`` of that seed on one machine: +0.30 ± 4.46 points zero-shot and −6.13 ± 4.31 held-out
over the three (a held-out loss on every seed, larger than its 328-1,337 fewer ray steps account for), so the recipe
keeps 2 to 8 source views per sample (docs/benchmarks.md, "Eight source views in every training sample")."""

HOUR_TWICE = "hour-2x"
"""Variant name of ``synth-cpu-hour`` exactly as it is but for its CPU budget, doubled (14,400 CPU s; its learning
rate decays over the budget, so over twice the steps). Why: over seven cells of the recipe on five machines, its
zero-shot and held-out mIoU rose with the ray steps the hour bought (+2.4 and +1.6 points per thousand), a line that
reaches the 60% held-out target at about 10,200 ray steps, where the fastest machine bought 6,575-8,236
(docs/benchmarks.md, "The recipe's three seeds on the fifth machine"). The cell asks whether the target is a matter of
compute: about 2.5 hours a seed on a 2-core machine, run in pieces resumed from its last checkpoint. Its seeds' scores
are in docs/benchmarks.md, "The recipe at twice its CPU budget"; it runs three seeds because one seed moves
held-out by about three points."""
