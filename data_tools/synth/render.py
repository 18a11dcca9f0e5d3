"""Render one view of a procedural room (RGB, z-depth, labels) by analytic ray casting through each pixel centre;
shading never depends on the camera (docs/data.md, "Appearance"), so views agree. Ceiling pixels are IGNORE_ID."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth.domains import view_gains
from sray.data_tools.synth.furniture import CLS
from sray.data_tools.synth.geometry import PackedBoxes, box_normals, cast_rays, cast_shell, in_frame
from sray.data_tools.synth.materials import UNLIT_KINDS
from sray.data_tools.synth.rooms import Room
from sray.data_tools.synth.textures import MaterialTable, albedo

SHELL_LABELS = (CLS["wall"], CLS["floor"], IGNORE_ID)
"""Labels of the shell surfaces: walls, floor, ceiling."""


@dataclass
class RenderScene:
    """A room prepared for rendering, with its camera: ``materials`` = the P boxes', then walls', floor's, ceiling's;
    ``tone`` (k, gamma) of rgb = (1 - exp(-k x)) ** (1 / gamma); ``noise_sigma`` in 8-bit levels; ``noise_seed`` seeds
    noise and view gains (``randomise``); ``tint``: white balance."""

    room: Room
    boxes: PackedBoxes
    materials: MaterialTable
    exposure: float
    tone: tuple[float, float] = (1.6, 2.2)
    noise_sigma: float = 0.0
    noise_seed: int = 0
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    randomise: float = 0.0

    @classmethod
    def prepare(cls, room: Room, exposure: float = 1.0, tone: tuple[float, float] = (1.6, 2.2),
                noise_sigma: float = 0.0, noise_seed: int = 0, tint: tuple[float, float, float] = (1.0, 1.0, 1.0),
                randomise: float = 0.0) -> RenderScene:
        """Pack a room's boxes and materials; the camera as the fields say."""
        boxes = PackedBoxes.from_boxes(room.boxes)
        shell_half = np.tile(np.array(room.size) / 2, (3, 1))
        table = MaterialTable.build(boxes.materials + [room.wall, room.floor, room.ceiling],
                                    np.concatenate([boxes.half, shell_half]),
                                    np.concatenate([boxes.quarter, [0, 0, 0]]))
        return cls(room=room, boxes=boxes, materials=table, exposure=exposure, tone=tone, noise_sigma=noise_sigma,
                   noise_seed=noise_seed, tint=tint, randomise=randomise)


def pixel_directions(K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """World ray directions R K^-1 [u, v, 1] of every pixel centre, float64 (H*W, 3), row-major."""
    h, w = hw
    v, u = np.meshgrid(np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64), indexing="ij")
    u, v = u.ravel(), v.ravel()
    k_inv = np.linalg.inv(K)
    cam = [k_inv[i, 0] * u + k_inv[i, 1] * v + k_inv[i, 2] for i in range(3)]
    rot = c2w[:3, :3]
    return np.stack([rot[i, 0] * cam[0] + rot[i, 1] * cam[1] + rot[i, 2] * cam[2] for i in range(3)], axis=1)


def visible_boxes(boxes: PackedBoxes, K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """bool (P,): boxes not entirely outside one of the view frustum's side or near planes."""
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64)
    local = corners[None, :, :] * boxes.half[:, None, :]
    world = in_frame(local, np.cos(boxes.yaw)[:, None], -np.sin(boxes.yaw)[:, None]) + boxes.center[:, None, :]
    cam = (world - c2w[:3, 3]) @ c2w[:3, :3]
    x, y, z = cam[..., 0], cam[..., 1], cam[..., 2]
    h, w = hw
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    outside = [z <= 1e-6, fx * x + (cx + 0.5) * z < 0, -fx * x + (w - 0.5 - cx) * z < 0,
               fy * y + (cy + 0.5) * z < 0, -fy * y + (h - 0.5 - cy) * z < 0]
    return ~np.any([np.all(o, axis=1) for o in outside], axis=0)


def _shell_frame(room: Room, points: np.ndarray, face: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texture coordinates, inward normals and face axis of shell hits (walls use along-wall, depth, z)."""
    lx, ly, _ = room.size
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    along = np.select([face == 0, face == 1, face == 2, face == 3], [ly - y, y, x, lx - x], x)
    depth = np.select([face == 0, face == 1, face == 2, face == 3], [x, lx - x, y, ly - y], z)
    wall = face < 4
    q = np.where(wall[:, None], np.stack([along, depth, z], 1), points)
    normals = np.zeros_like(points)
    axis = face // 2
    normals[np.arange(len(points)), axis] = np.where(face % 2 == 0, 1.0, -1.0)
    return q, normals, np.where(wall, 1, 2)


def _edge_occlusion(room: Room, points: np.ndarray) -> np.ndarray:
    """Ambient darkening near the room's edges and corners, from the two nearest shell planes (N,)."""
    lx, ly, h = room.size
    d = np.stack([points[:, 0], lx - points[:, 0], points[:, 1], ly - points[:, 1], points[:, 2], h - points[:, 2]], 1)
    second = np.sort(np.abs(d), axis=1)[:, 1]
    return 1.0 - 0.35 * np.exp(-second / 0.35)


def _lighting(scene: RenderScene, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Linear RGB irradiance factor (N, 3) at surface points with outward normals."""
    room = scene.room
    light = np.ones((len(points), 3), np.float32) * (room.ambient * _edge_occlusion(room, points))[:, None]
    for k, lamp in enumerate(room.lights):
        to_light = np.asarray(lamp.position) - points
        dist = np.linalg.norm(to_light, axis=1)
        cosine = np.maximum(0.0, np.sum(normals * to_light, axis=1) / np.maximum(dist, 1e-6))
        falloff = 4.0 / (4.0 + dist**2)
        gain = lamp.intensity * cosine * falloff
        if k == 0 and np.any(cosine > 0):
            lit = cosine > 0
            source = np.asarray(lamp.position, np.float64)
            # only boxes meeting the bounding box of the light and the lit points can cast a shadow on them
            span = np.concatenate([points[lit], source[None, :]])
            casters = scene.boxes.casts_shadow & scene.boxes.overlaps(span.min(axis=0), span.max(axis=0))
            t_hit, _ = cast_rays(source, points[lit] - source, scene.boxes, active=casters)
            shadow = np.zeros(len(points), bool)
            shadow[lit] = t_hit < 1.0 - 0.005 / np.maximum(dist[lit], 1e-3)
            gain = np.where(shadow, 0.0, gain)
        light += gain[:, None] * np.asarray(lamp.color, np.float32)[None, :]
    return light


def render_view(scene: RenderScene, K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int], view_index: int = 0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Render (rgb uint8 (H, W, 3), z-depth float32 (H, W) metres, label uint16 (H, W)); ``view_index`` seeds noise."""
    h, w = hw
    origin = np.asarray(c2w, np.float64)[:3, 3]
    dirs = pixel_directions(np.asarray(K, np.float64), np.asarray(c2w, np.float64), hw)
    t_box, i_box = cast_rays(origin, dirs, scene.boxes, active=visible_boxes(scene.boxes, K, c2w, hw))
    t_shell, face = cast_shell(origin, dirs, scene.room.size)
    on_box = t_box < t_shell
    t = np.where(on_box, t_box, t_shell)
    points = origin[None, :] + t.astype(np.float64)[:, None] * dirs

    n_boxes = len(scene.boxes)
    surface = np.where(on_box, i_box, n_boxes + np.select([face < 4, face == 4], [0, 1], 2))
    label = np.where(on_box, scene.boxes.label[np.maximum(i_box, 0)],
                     np.select([face < 4, face == 4], [SHELL_LABELS[0], SHELL_LABELS[1]], SHELL_LABELS[2]))
    q, normals, n_axis = _shell_frame(scene.room, points, face)
    if on_box.any():
        idx = i_box[on_box]
        local = scene.boxes.to_local(idx, points[on_box])
        normals[on_box], n_axis[on_box] = box_normals(scene.boxes, idx, local)
        q[on_box] = local

    colour = albedo(scene.materials, surface, q, n_axis)
    lit = ~np.isin(scene.materials.kind[surface], UNLIT_KINDS)
    colour[lit] *= _lighting(scene, points[lit], normals[lit]) * scene.exposure
    if scene.randomise > 0 or scene.tint != (1.0, 1.0, 1.0):
        gains = np.asarray(scene.tint) * view_gains(scene.randomise, np.random.default_rng([scene.noise_seed,
                                                                                            view_index, 1]))
        colour *= gains.astype(np.float32)[None, :]
    k, gamma = scene.tone
    encoded = 255.0 * np.clip(1.0 - np.exp(-k * colour), 0, 1) ** (1 / gamma)
    if scene.noise_sigma > 0:
        encoded = encoded + np.random.default_rng([scene.noise_seed, view_index]).normal(0.0, scene.noise_sigma,
                                                                                         encoded.shape)
    rgb = np.round(np.clip(encoded, 0.0, 255.0)).astype(np.uint8)
    return rgb.reshape(h, w, 3), t.reshape(h, w).astype(np.float32), label.reshape(h, w).astype(np.uint16)
