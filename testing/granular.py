"""The truth on a granular material's texture: scikit-image's gravel photograph (grains about 16 px),
area-averaged so that a pixel spans as many grains as a render draws."""
import cv2
import numpy as np
from skimage import data


def texture(luma: np.ndarray, margin: int) -> float:
    """The spread of each pixel's luma (H, W) over its neighbourhood's mean (a Gaussian of 2 px), ``margin`` px
    from the border left out."""
    ratio = luma / cv2.GaussianBlur(luma, (0, 0), 2.0, borderType=cv2.BORDER_REFLECT)
    return float(ratio[margin:-margin, margin:-margin].std())


def gravel_texture(grains_a_pixel: float) -> float:
    """texture of scikit-image's gravel photograph (grains about 16 px) area-averaged so that a pixel spans
    ``grains_a_pixel`` grains."""
    gravel = data.gravel().astype(float)
    n = int(round(gravel.shape[0] / (16 * grains_a_pixel)))
    return texture(cv2.resize(gravel, (n, n), interpolation=cv2.INTER_AREA), 2)
