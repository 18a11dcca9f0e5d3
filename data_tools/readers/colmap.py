"""Reader: a COLMAP capture (``sparse/0/{cameras,images,points3D}.{bin,txt}`` + ``images/``), unlabelled: poses by
``colmap_model.image_c2w``, cameras by ``camera_models.colmap_camera``, bounds from each image's points, scale from
``--scale``, frames in name order (docs/capture.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sray.data_tools.readers.camera_models import colmap_camera
from sray.data_tools.readers.capture import CaptureFrame, capture_scene
from sray.data_tools.readers.colmap_model import find_model, image_c2w, read_model
from sray.data_tools.scene import Scene


def read_colmap(src: Path, name: str, label_space: str = "scannet20", size_hw: tuple[int, int] | None = (240, 320),
                frame_skip: int = 1, depth_scale: float = 1000.0, scale: float | None = None,
                images: Path | None = None, sparse: Path | None = None) -> Scene:
    """Open a COLMAP capture as an unlabelled scene (views load lazily): ``scale`` metres per model unit, ``images`` the
    image folder (default ``SRC/images``), ``sparse`` the model (default ``find_model``)."""
    src = Path(src)
    folder = Path(sparse) if sparse is not None else find_model(src)
    model = read_model(folder)
    image_dir = Path(images) if images is not None else src / "images"
    if not image_dir.is_dir():
        raise FileNotFoundError(f"{image_dir}: missing image folder; pass --images with the folder COLMAP read")
    frames = []
    for image in sorted(model.images.values(), key=lambda im: im.name):
        cam = model.cameras[image.camera_id]
        camera = colmap_camera(cam.model, cam.params, (cam.height, cam.width),
                               f"{folder}: camera {cam.camera_id} ({cam.model})")
        path = image_dir / image.name
        if not path.is_file():
            raise FileNotFoundError(f"{path}: image {image.image_id} of {folder} is missing; pass --images")
        seen = [model.points[i] for i in image.point3d_ids.tolist() if i in model.points]
        frames.append(CaptureFrame(image=path, camera=camera, c2w=image_c2w(image, f"{folder}"),
                                   seen_points=np.array(seen).reshape(-1, 3)))
    points = np.array(list(model.points.values())).reshape(-1, 3)
    return capture_scene(frames, points, src=src, name=name, source_format="colmap", label_space=label_space,
                         size_hw=size_hw, frame_skip=frame_skip, depth_scale=depth_scale, scale=scale,
                         extra={"colmap_model": str(folder),
                                "colmap_form": "binary" if (folder / "cameras.bin").is_file() else "text"})
