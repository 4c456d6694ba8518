"""Floor-plan images on the desktop: grey levels for :func:`core.indoor.raster.walls_from_image` (Pillow).

Pillow is a desktop dependency (the ``desktop`` extra), not the phone's: ``core`` takes the grey array,
and the phone gets the walls extracted here and shipped as GeoJSON (``core.indoor.write_geojson``).
"""

from __future__ import annotations

import numpy as np


def read_floor_image(path) -> np.ndarray:
    """Grey levels ``(rows, cols)`` (float 0-255) of an image file; transparent pixels become white."""
    from PIL import Image  # noqa: PLC0415 - imported when called

    Image.MAX_IMAGE_PIXELS = None  # floor plans are large (the IPIN map is 54 Mpx)
    with Image.open(str(path)) as im:
        im.load()
        if im.mode in ("RGBA", "LA", "PA") or (im.mode == "P" and "transparency" in im.info):
            la = np.asarray(im.convert("LA"), dtype=np.float32)
            a = la[..., 1] / 255.0
            return la[..., 0] * a + 255.0 * (1.0 - a)
        return np.asarray(im.convert("L"), dtype=np.float32)
