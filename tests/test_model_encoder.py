"""The ResUNet encoder follows the appendix table's shapes at any first-layer width, keeps pixel centres aligned, and
normalises every layer per image with instance norm."""

from __future__ import annotations

import pytest
import torch

from sray.model.config import SRayConfig
from sray.model.encoder import ResUNetEncoder, upsample_to
from sray.model.semantic_ray import SRayModel
from sray.platform.eval.segmenter import Segmenter, SegmenterConfig


@pytest.mark.parametrize("hw", [(48, 64), (120, 160), (33, 47)])
def test_stage_shapes_follow_the_table(hw: tuple[int, int]) -> None:
    torch.manual_seed(0)
    enc = ResUNetEncoder(32)
    seen = {}
    for name in ("stem", "down2", "down3", "down4", "merge3"):
        getattr(enc, name).register_forward_hook(lambda _m, _i, out, name=name: seen.__setitem__(name, out.shape))
    out = enc(torch.rand(2, 3, *hw))

    def down(size: int, times: int) -> int:
        for _ in range(times):
            size = -(-size // 2)
        return size

    h, w = hw
    expected = {"stem": (2, 16, down(h, 1), down(w, 1)), "down2": (2, 32, down(h, 2), down(w, 2)),
                "down3": (2, 64, down(h, 3), down(w, 3)), "down4": (2, 128, down(h, 4), down(w, 4)),
                "merge3": (2, 32, down(h, 3), down(w, 3))}
    assert {k: tuple(v) for k, v in seen.items()} == expected
    assert out.shape == (2, 32, down(h, 2), down(w, 2))
    assert torch.isfinite(out).all()


def test_upsampling_reads_coarse_coordinate_half_j() -> None:
    coarse = torch.arange(5.0).view(1, 1, 1, 5).expand(1, 1, 3, 5) * 2 + torch.arange(3.0).view(1, 1, 3, 1)
    up = upsample_to(coarse, (6, 10))  # value at (i, j) should be coarse(i / 2, j / 2), clamped
    j = torch.arange(10.0).clamp(max=8) / 2
    i = torch.arange(6.0).clamp(max=4) / 2
    torch.testing.assert_close(up[0, 0], j.view(1, 10) * 2 + i.view(6, 1), rtol=0, atol=1e-6)


def test_encoder_is_per_image_and_rejects_tiny_images() -> None:
    torch.manual_seed(1)
    enc = ResUNetEncoder(32)
    imgs = torch.rand(3, 3, 40, 48)
    torch.testing.assert_close(enc(imgs)[1:2], enc(imgs[1:2]), rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="at least 32"):
        enc(torch.rand(1, 3, 24, 64))


def _table_parameters(w: int, out_dim: int) -> int:
    """Learned parameters of the appendix table's layers with L1 ``w`` channels wide, counted from the table:
    bias-free convolutions, an affine instance norm (2 per channel) after each, 1x1 projections on the ResBlocks
    whose shape changes."""
    def conv(c_in: int, c_out: int, k: int) -> int:
        return c_in * c_out * k * k + 2 * c_out

    def res(c_in: int, c_out: int) -> int:
        return conv(c_in, c_out, 3) + conv(c_out, c_out, 3) + (conv(c_in, c_out, 1) if c_in != c_out else 0)

    down = conv(3, w, 7) + res(w, 2 * w) + res(2 * w, 4 * w) + res(4 * w, 4 * w) + res(4 * w, 8 * w) \
        + 5 * res(8 * w, 8 * w)
    up = conv(8 * w, 4 * w, 3) + conv(8 * w, 4 * w, 3) + conv(4 * w, 2 * w, 3) + conv(4 * w, 2 * w, 3) \
        + conv(2 * w, out_dim, 1)
    return down + up


@pytest.mark.parametrize("width", [8, 16, 24])
def test_every_layer_scales_with_the_first_layers_width(width: int) -> None:
    enc = ResUNetEncoder(32, width)
    seen = {}
    for name in ("stem", "down2", "down3", "down4", "reduce4", "merge3", "merge2"):
        getattr(enc, name).register_forward_hook(lambda _m, _i, out, name=name: seen.__setitem__(name, out.shape[1]))
    assert enc(torch.rand(1, 3, 48, 64)).shape == (1, 32, 12, 16)
    assert seen == {"stem": width, "down2": 2 * width, "down3": 4 * width, "down4": 8 * width, "reduce4": 4 * width,
                    "merge3": 2 * width, "merge2": 2 * width}
    assert sum(p.numel() for p in enc.parameters()) == _table_parameters(width, 32)
    model_encoder = SRayModel(SRayConfig(n_classes=5, encoder_width=width)).encoder
    segmenter_encoder = Segmenter(SegmenterConfig(n_classes=5, encoder_width=width)).encoder
    for built in (model_encoder, segmenter_encoder):
        assert [p.shape for p in built.parameters()] == [p.shape for p in enc.parameters()]


def test_a_width_below_one_is_refused_by_the_config() -> None:
    with pytest.raises(ValueError, match="encoder_width"):
        SRayConfig(encoder_width=0)


def _normalised_by_hand(x: torch.Tensor, groups: int, weight: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    """x (B, C, H, W) standardised over each image's groups of C / groups channels (biased variance, eps 1e-5),
    then scaled and shifted per channel: a naive loop over images and groups."""
    out = torch.empty_like(x)
    size = x.shape[1] // groups
    for b in range(x.shape[0]):
        for g in range(groups):
            block = x[b, g * size:(g + 1) * size].double()
            mean, var = block.mean(), ((block - block.mean()) ** 2).mean()
            out[b, g * size:(g + 1) * size] = ((block - mean) / torch.sqrt(var + 1e-5)).float()
    return out * weight.view(1, -1, 1, 1) + bias.view(1, -1, 1, 1)


def test_every_layer_normalises_each_channel_of_each_image() -> None:
    torch.manual_seed(2)
    enc = ResUNetEncoder(32, 16)
    norms = [m for m in enc.modules() if isinstance(m, torch.nn.InstanceNorm2d)]
    assert len(norms) == 27  # L1, 16 convs and 4 projections of the 10 ResBlocks, L11, L14, L15, L18, L19
    seen = []
    for layer in norms:
        with torch.no_grad():  # a non-trivial affine map, so scale and shift are checked too
            layer.weight.uniform_(0.5, 1.5)
            layer.bias.uniform_(-0.5, 0.5)
        layer.register_forward_hook(lambda m, i, out: seen.append((m, i[0], out)))
    with torch.no_grad():
        enc(torch.rand(2, 3, 48, 64))
    assert len(seen) == 27
    for layer, x, out in seen:
        channels = x.shape[1]
        torch.testing.assert_close(out, _normalised_by_hand(x, channels, layer.weight, layer.bias), rtol=1e-4,
                                   atol=1e-4)
