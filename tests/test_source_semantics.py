"""Dense 2D supervision of the encoder: the source-view head and loss against hand computations, the 2D
warm-up step, the train config's guards, and the loader's source labels (values, and which views they
may come from)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scene_fixtures
import torch
import torch.nn.functional as F
from label_reads import record_label_reads

from sray.data_tools.loader.class_stats import count_pixels, shard_pixel_counts
from sray.data_tools.loader.augment import Augmentation, rescale_nearest
from sray.data_tools.loader.samples import train_sample
from sray.data_tools.loader.shard_loader import make_train_loader
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.scene import IGNORE_ID, SceneMeta, source_pool
from sray.data_tools.shards.manifest import read_manifest
from sray.data_tools.shards.writer import write_shards
from sray.model.config import SRayConfig
from sray.model.ray_batch import QueryRays, RayBatch, RayBatchLoss
from sray.model.runtime import Runtime
from sray.model.source_semantics import SourceSemanticHead, source_semantic_loss
from sray.platform.config.train_config import TrainConfig, apply_override

H, W, M, R, L = 32, 40, 2, 24, 5


def _cfg(**changes: object) -> SRayConfig:
    base = dict(n_classes=L, feat_dim=8, n_coarse=4, n_fine=4, n_source=M, lambda_src_sem=0.5)
    return SRayConfig(**(base | changes))


def test_source_loss_is_the_hand_computed_weighted_cross_entropy() -> None:
    """Mean over labelled pixels of -w[y] log softmax(z)[y] / mean weight, in a float64 loop; ignored pixels
    count nowhere; an all-ignored batch gives exactly 0."""
    g = torch.Generator().manual_seed(0)
    logits = torch.randn(2, L, 3, 4, generator=g)
    labels = torch.randint(0, L, (2, 3, 4), generator=g)
    labels[0, 0] = IGNORE_ID
    weights = (0.5, 1.0, 2.0, 1.5, 0.25)
    for cfg_weights in ((), weights):
        num = den = 0.0
        for v, y, x in np.ndindex(2, 3, 4):
            c = int(labels[v, y, x])
            if c == IGNORE_ID:
                continue
            w = cfg_weights[c] if cfg_weights else 1.0
            z = logits[v, :, y, x].double()
            num += -w * float(z[c] - torch.logsumexp(z, 0))
            den += w
        got = source_semantic_loss(logits, labels, _cfg(class_weights=cfg_weights))
        assert float(got) == pytest.approx(num / den, rel=1e-5)
    empty = torch.full_like(labels, IGNORE_ID)
    leaf = logits.clone().requires_grad_()
    zero = source_semantic_loss(leaf, empty, _cfg())
    zero.backward()
    assert float(zero.detach()) == 0.0 and float(leaf.grad.abs().sum()) == 0.0


def test_head_logits_sit_on_the_feature_pixel_centres() -> None:
    """Feature pixel j is centred on image pixel 4j: the full-size logits there equal the 1x1 read-out of that
    feature, and the pixel halfway between two feature centres is their mean (bilinear, centre-aligned)."""
    torch.manual_seed(0)
    head = SourceSemanticHead(_cfg())
    feats = torch.randn(M, 8, 8, 10)  # the encoder's grid for 32 x 40 images
    with torch.no_grad():
        logits = head(feats, (H, W))  # (M, L, H, W)
        direct = head.classify(feats)  # (M, L, 8, 10)
    assert logits.shape == (M, L, H, W)
    torch.testing.assert_close(logits[..., ::4, ::4], direct, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(logits[..., 4 * 2 + 2, 4 * 3], (direct[..., 2, 3] + direct[..., 3, 3]) / 2,
                               rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="do not belong"):
        head(feats, (64, 80))


def _batch(seed: int = 0, labelled: bool = True) -> RayBatch:
    g = torch.Generator().manual_seed(seed)
    K = torch.tensor([[28.0, 0.0, (W - 1) / 2], [0.0, 28.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
    c2w = torch.eye(4).repeat(M, 1, 1)
    c2w[:, 0, 3] = torch.tensor([-0.2, 0.2])
    query = QueryRays(K=K, c2w=torch.eye(4), pixels=torch.rand(R, 2, generator=g) * torch.tensor([W - 1.0, H - 1.0]),
                      near=1.0, far=4.0)
    rgb = torch.rand(M, 3, H, W, generator=g)
    label = torch.randint(0, L, (M, H, W), generator=g) if labelled else None
    return RayBatch(src_rgb=rgb, src_K=K.expand(M, 3, 3).clone(), src_c2w=c2w,
                    query=query, src_label=label)


def _targets(seed: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    return torch.randint(0, L, (R,), generator=g), torch.rand(R, 3, generator=g)


def test_a_step_adds_lambda_times_the_source_term_to_the_ray_loss() -> None:
    """Same seed: loss with source labels = loss without + lambda_src_sem x the head's cross-entropy computed
    here from the encoder's features; without labels the term is absent."""
    torch.manual_seed(0)
    model = RayBatchLoss(_cfg(), Runtime(train_piece=R))
    batch, (label, rgb) = _batch(), _targets()
    torch.manual_seed(5)
    with_term, terms = model(batch, label, rgb)
    torch.manual_seed(5)
    without, plain_terms = model(_batch(labelled=False), label, rgb)
    with torch.no_grad():
        feats = model.net.encoder(batch.src_rgb)
        expected = F.cross_entropy(model.net.src_head(feats, (H, W)), batch.src_label)
    assert "sem_src" in terms and "sem_src" not in plain_terms
    torch.testing.assert_close(terms["sem_src"], expected, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(with_term.detach(), without.detach() + 0.5 * expected, rtol=1e-5, atol=1e-6)


def test_the_2d_warm_up_step_renders_nothing_and_moves_only_encoder_and_head(monkeypatch: pytest.MonkeyPatch) -> None:
    """``render=False``: the loss is lambda x the source term, nothing is rendered, every parameter has a
    gradient (DDP needs one), and outside the encoder and the head it is exactly zero."""
    torch.manual_seed(0)
    model = RayBatchLoss(_cfg())

    def no_render(*args: object, **kwargs: object) -> None:
        raise AssertionError("the 2D warm-up rendered rays")

    monkeypatch.setattr(model.net, "training_loss", no_render)
    loss, terms = model(_batch(), *_targets(), render=False)
    loss.backward()
    torch.testing.assert_close(loss.detach(), 0.5 * terms["sem_src"])
    for name, p in model.named_parameters():
        assert p.grad is not None, name
        trained = name.startswith(("net.encoder.", "net.src_head."))
        assert (float(p.grad.abs().sum()) > 0) == trained or (trained and "norm" in name), name
    with pytest.raises(ValueError, match="lambda_src_sem"):
        model(_batch(labelled=False), *_targets(), render=False)


def test_the_head_exists_only_with_a_positive_weight_and_the_config_guards_the_warm_up() -> None:
    """No head (so no extra checkpoint keys) at lambda_src_sem = 0; a warm-up without the head, or a negative
    weight, is refused naming the field, and a refused override leaves the config as it was."""
    assert RayBatchLoss(_cfg(lambda_src_sem=0.0)).net.src_head is None
    assert not any(k.startswith("src_head") for k in RayBatchLoss(_cfg(lambda_src_sem=0.0)).net.state_dict())
    with pytest.raises(ValueError, match="lambda_src_sem"):
        _cfg(lambda_src_sem=-1.0)
    cfg = TrainConfig()
    with pytest.raises(ValueError, match="warmup_2d_steps"):
        apply_override(cfg, "optim.warmup_2d_steps=10")
    assert cfg.optim.warmup_2d_steps == 0
    apply_override(cfg, "model.lambda_src_sem=1")
    apply_override(cfg, "optim.warmup_2d_steps=10")
    assert TrainConfig.from_dict(cfg.to_dict()).optim.warmup_2d_steps == 10


@pytest.fixture(scope="module")
def shards(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two 12-view train scenes and one 12-view unseen test scene, 30x40 pixels."""
    root = tmp_path_factory.mktemp("source_labels")
    scenes = scene_fixtures.write_dataset(root / "scenes", [("a", 12, "train"), ("b", 12, "train"),
                                                            ("t", 12, "test")])
    write_shards(scenes, root / "shards", views_per_shard=6, neighbours=10, progress=False)
    return root / "shards"


def test_source_labels_are_the_stored_maps_resized_with_their_images(shards: Path) -> None:
    """Plain samples carry the stored label maps; resized sources carry them resized by nearest pixel centre
    to the images' size; without the flag no labels travel."""
    views = read_scene_views(shards, read_manifest(shards).scenes["a"])
    ids = sorted(views)
    plain = train_sample(views, ids[0], ids[1:4], 8, np.random.default_rng(0), "a", 0.5, 6.0, 20,
                         source_labels=True)
    stored = np.stack([views[s].label() for s in ids[1:4]]).astype(np.int64)
    assert torch.equal(plain.sources.label, torch.from_numpy(stored))
    resized = train_sample(views, ids[0], ids[1:4], 8, np.random.default_rng(0), "a", 0.5, 6.0, 20,
                           Augmentation(source_scale=0.5), source_labels=True)
    size = tuple(resized.sources.rgb.shape[-2:])
    assert size != stored.shape[-2:]
    expected = np.stack([rescale_nearest(views[s].label(), size) for s in ids[1:4]]).astype(np.int64)
    assert torch.equal(resized.sources.label, torch.from_numpy(expected))
    assert train_sample(views, ids[0], ids[1:4], 8, np.random.default_rng(0), "a", 0.5, 6.0, 20).sources.label is None


def test_source_labels_come_only_from_training_views_of_training_scenes(shards: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Every label map the training loader decodes (queries' and sources') belongs to a train scene's source
    pool: never a test scene's view, never a held-out view of a train scene."""
    read = record_label_reads(monkeypatch)
    loader = make_train_loader(shards, n_source=3, top_k=8, rays_per_batch=8, batches_per_epoch=40, rank=0,
                               world_size=1, num_workers=0, seed=3, source_labels=True,
                               augment=Augmentation(min_source=2))
    samples = list(loader)
    assert all(s.sources.label is not None for s in samples)
    manifest = read_manifest(shards)
    allowed = {(name, v) for name, entry in manifest.scenes.items() if entry.meta.get("role") == "train"
               for v in source_pool(SceneMeta.from_json(entry.meta))}
    seen = set(read)
    assert seen and seen <= allowed
    assert len(seen) > 12  # sources beyond the queries were read


def test_class_weight_counts_read_only_the_views_training_reads(shards: Path) -> None:
    """The class-frequency counts behind ``data.class_balance`` cover each train scene's source pool: its
    held-out views' labels are not counted (the independent count here skips them by the split)."""
    names, per_scene = shard_pixel_counts(shards, roles=("train",))
    manifest = read_manifest(shards)
    assert set(per_scene) == {"a", "b"}
    for scene, counts in per_scene.items():
        meta = SceneMeta.from_json(manifest.scenes[scene].meta)
        views = read_scene_views(shards, manifest.scenes[scene])
        held_out = set(meta.splits["test"])
        assert held_out and not held_out & set(source_pool(meta))
        expected = count_pixels((views[v].label() for v in meta.view_ids if v not in held_out), len(names))
        np.testing.assert_array_equal(counts, expected)
