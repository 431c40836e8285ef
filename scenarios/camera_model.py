"""A camera model: what a real camera makes of the light reaching its sensor.

:func:`capture` takes a linear-light BGR image (scene-referred, any scale: a renderer's radiance) and gives
back what a decoder returns from the camera's stream, with the encoded bytes. The stages, in order, each a
small pure function of this module (docs/camera-model.md says why each is there and why its defaults):

1. **exposure** (:func:`auto_exposure`, :func:`expose`): a fixed multiplier, or auto exposure like an AE loop's
   settled state: the scene's median luminance lands at ``ae_target`` of saturation unless that would put the
   ``ae_highlight_percentile`` above ``ae_highlight_level``; ``exposure_bias_ev`` on top. After this stage
   1.0 is the sensor's saturation (the full well).
2. **white balance** (:func:`white_balance`): per-channel gains (BGR), an AWB error.
3. **lens blur** (:func:`lens_blur`): a Gaussian of ``lens_blur_px`` (sigma, pixels) on the light: a soft lens.
4. **motion blur** (:func:`motion_blur`): a line kernel of ``motion_blur_px`` at ``motion_blur_angle_deg``.
5. **colour filter mosaic** (:func:`mosaic`): one colour per photosite, ``bayer`` naming the top-left 2x2.
6. **sensor** (:func:`sensor`): shot noise (Poisson in electrons, ``full_well`` electrons at saturation),
   read noise (Gaussian, ``read_noise`` electrons), an ADC of ``bit_depth`` bits that clips.
7. **demosaicing** (:func:`demosaic`): OpenCV's bilinear, VNG or edge-aware Bayer conversions.
8. **tone curve** (:func:`tone_lut`): sRGB, a gamma or a filmic curve, to 8 bits; or one of Blender's view
   transforms (``blender-agx``, ``blender-filmic``, ...), a 3D LUT baked from Blender (:mod:`scenarios.view_luts`)
   applied to the sensor level as Blender's scene-linear value.
9. **colour** (:func:`colour_adjust`): ``saturation`` scales the chroma about the luma, ``hue_rotation_deg``
   rotates it (the YCbCr plane of the 8-bit values), as a camera's saturation setting and hue error.
10. **encoding** (:func:`encode`): JPEG at ``jpeg_quality`` with 4:2:0 or 4:4:4 chroma, or lossless PNG;
    the image is the decoded stream.

The defaults of the stages added for other looks (3, the Blender tones of 8, 9) leave an image bit for bit what it
was before them; :func:`spec_record` writes a spec without those fields while they are at their defaults.

Every random draw comes from the ``rng`` passed in: the same seed captures the same image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Annotated, Any, Literal

import cv2
import numpy as np
from pydantic import Field, field_validator

from .documents import Strict
from .view_luts import VIEW_TONES, view_transform, view_transform_codes

Bayer = Literal["RGGB", "BGGR", "GRBG", "GBRG", "none"]

#: Rec. 709 luminance weights of linear B, G, R (metering).
LUMA_BGR = np.array([0.0722, 0.7152, 0.2126], np.float32)
#: Auto exposure meters every METER_STEP-th row and column (a metering grid, as cameras do: ~20k samples at VGA).
METER_STEP = 4
#: Below this mean (electrons) shot noise is drawn from the Poisson law; above it from its normal approximation
#: N(mean, mean), which is exact to a skew of 1/sqrt(mean) < 0.1 and ~6x faster (docs/camera-model.md).
POISSON_BELOW = 100.0
#: OpenCV names a Bayer pattern by the second row's 2nd and 3rd photosites: our top-left 2x2 ``RGGB`` is its ``BG``.
_OPENCV_BAYER = {"RGGB": "BG", "BGGR": "RG", "GRBG": "GB", "GBRG": "GR"}
#: Channel (B=0, G=1, R=2) of each photosite of the top-left 2x2, row by row.
_PATTERN_CHANNELS = {"RGGB": (2, 1, 1, 0), "BGGR": (0, 1, 1, 2), "GRBG": (1, 2, 0, 1), "GBRG": (1, 0, 2, 1)}
#: John Hable's filmic curve constants (shoulder, linear, toe), and the linear white it is normalised at.
_HABLE = (0.15, 0.50, 0.10, 0.20, 0.02, 0.30)
FILMIC_WHITE = 4.0
#: The tone curves: three 1-D curves, and Blender's view transforms (:data:`scenarios.view_luts.VIEW_TONES`).
Tone = Literal["srgb", "gamma", "filmic", "blender-standard", "blender-agx", "blender-agx-punchy", "blender-filmic",
               "blender-filmic-high-contrast", "blender-khronos-pbr-neutral"]
#: Fields added for looks (docs/camera-model.md, "Looks") and their defaults, which change nothing:
#: :func:`spec_record` leaves them out at these values so that a dataset's manifest stays what it was.
LOOK_FIELD_DEFAULTS = {"lens_blur_px": 0.0, "saturation": 1.0, "hue_rotation_deg": 0.0}
#: BGR -> (Y, Cb, Cr) of the 8-bit values (BT.601, JPEG's YCbCr, without the 128 offset): the colour stage's plane.
_YCBCR_FROM_BGR = np.array([[0.114, 0.587, 0.299],
                            [0.5, -0.331264, -0.168736],
                            [-0.081312, -0.418688, 0.5]], np.float64)


class CameraModelSpec(Strict):
    """A camera's sensor, processing and encoder (the world's ``render.camera_model``); the defaults are a small
    industrial colour camera streaming JPEG (docs/camera-model.md)."""

    #: ``auto``, or a fixed multiplier from the input's scale to the sensor's (1.0 = saturation).
    exposure: Literal["auto"] | Annotated[float, Field(gt=0, le=1e9)] = "auto"
    #: Exposure compensation, stops (applied on top of either mode).
    exposure_bias_ev: Annotated[float, Field(ge=-10, le=10)] = 0.0
    #: Auto exposure: the median luminance's level (fraction of saturation; 0.18 = mid-grey).
    ae_target: Annotated[float, Field(gt=0, lt=1)] = 0.18
    #: Auto exposure: this percentile of the luminance may reach at most ``ae_highlight_level``.
    ae_highlight_percentile: Annotated[float, Field(ge=50, le=100)] = 99.0
    ae_highlight_level: Annotated[float, Field(gt=0, le=1)] = 0.95
    #: White balance gains, B, G, R (like every colour of the project): an AWB error is e.g. [0.95, 1, 1.05].
    white_balance: Annotated[list[Annotated[float, Field(gt=0, le=10)]], Field(min_length=3, max_length=3)] = \
        [1.0, 1.0, 1.0]
    #: Lens blur: a Gaussian's sigma (pixels) on the light before the mosaic (a soft or defocused lens).
    lens_blur_px: Annotated[float, Field(ge=0, le=50)] = 0.0
    #: Motion blur during the exposure: the streak's length (pixels) and direction (degrees from the image's +u).
    motion_blur_px: Annotated[float, Field(ge=0, le=200)] = 0.0
    motion_blur_angle_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0
    #: Colour filter array, the top-left 2x2 read row by row (``none``: a three-chip camera, no mosaic).
    bayer: Bayer = "RGGB"
    #: Electrons at saturation (shot noise: SNR = sqrt(electrons)).
    full_well: Annotated[float, Field(ge=10, le=1e7)] = 10000.0
    #: Read noise, electrons RMS.
    read_noise: Annotated[float, Field(ge=0, le=1e4)] = 5.0
    #: ADC bits (the raw values are 0 .. 2**bit_depth - 1).
    bit_depth: Annotated[int, Field(ge=8, le=16)] = 12
    demosaic: Literal["bilinear", "vng", "edge-aware"] = "bilinear"
    #: Tone curve: ``srgb``, ``gamma``, ``filmic`` (Hable), or a Blender view transform (:data:`VIEW_TONES`).
    tone: Tone = "srgb"
    #: Display gamma of ``tone: gamma`` (out = in ** (1 / gamma)).
    gamma: Annotated[float, Field(ge=1, le=4)] = 2.2
    #: Saturation: the chroma (Cb, Cr of the 8-bit image) times this after the tone curve; 1 = unchanged.
    saturation: Annotated[float, Field(ge=0.2, le=3)] = 1.0
    #: Hue error: the chroma rotated by this angle (degrees; + turns red towards yellow, as HSV's hue).
    hue_rotation_deg: Annotated[float, Field(ge=-180, le=180)] = 0.0
    #: JPEG quality 1-100, or null for lossless PNG.
    jpeg_quality: Annotated[int, Field(ge=1, le=100)] | None = 85
    #: JPEG chroma subsampling: ``420`` (half resolution colour, what cameras stream) or ``444``.
    chroma: Literal["420", "444"] = "420"

    @field_validator("chroma", mode="before")
    @classmethod
    def _chroma_text(cls, value: Any) -> Any:
        return str(value) if isinstance(value, int) and not isinstance(value, bool) else value


@dataclass(frozen=True, eq=False)
class Captured:
    """A captured frame: the decoded ``image`` (uint8 BGR, (H, W, 3)), the ``encoded`` bytes and their
    file ``suffix`` (``.jpg`` or ``.png``)."""

    image: np.ndarray
    encoded: bytes
    suffix: str


# --- sRGB ------------------------------------------------------------------------------------------------------

def _srgb_decode(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _srgb_encode(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


_SRGB_TO_LINEAR = _srgb_decode(np.arange(256) / 255.0).astype(np.float32)
#: Linear levels of the table of :func:`srgb_from_linear` (16 bits: 0.05 sRGB levels at black, exact round trips).
_ENCODE_STEPS = 65535
_LINEAR_TO_SRGB = np.round(_srgb_encode(np.arange(_ENCODE_STEPS + 1) / _ENCODE_STEPS) * 255.0).astype(np.uint8)


def linear_from_srgb(image: np.ndarray) -> np.ndarray:
    """sRGB-encoded values 0-255 (uint8 image, or any array such as a palette colour) -> linear float32 0-1."""
    a = np.asarray(image)
    if a.dtype == np.uint8:
        image_like = a.ndim == 2 or (a.ndim == 3 and a.shape[2] <= 4)  # what cv2.LUT takes (4x faster)
        return cv2.LUT(a, _SRGB_TO_LINEAR) if image_like else _SRGB_TO_LINEAR[a]
    return _srgb_decode(np.clip(a.astype(np.float64), 0, 255) / 255.0).astype(np.float32)


def srgb_from_linear(linear: np.ndarray) -> np.ndarray:
    """Linear values (1.0 = white, clipped to 0-1) -> sRGB-encoded uint8 (through a 16-bit table: fast)."""
    scaled = np.clip(np.asarray(linear, np.float32) * np.float32(_ENCODE_STEPS) + np.float32(0.5), 0, _ENCODE_STEPS)
    return _LINEAR_TO_SRGB[scaled.astype(np.uint16)]


# --- the stages ------------------------------------------------------------------------------------------------

def luminance(image: np.ndarray) -> np.ndarray:
    """Linear luminance of a linear BGR image, shape (H, W)."""
    return image @ LUMA_BGR


def auto_exposure(radiance: np.ndarray, spec: CameraModelSpec) -> float:
    """The multiplier that puts the metered median luminance at ``ae_target`` and keeps the highlight percentile
    at or below ``ae_highlight_level`` (1.0 for a black scene)."""
    meter = luminance(np.asarray(radiance[::METER_STEP, ::METER_STEP], np.float32)).ravel()
    median, high = np.percentile(meter, [50.0, spec.ae_highlight_percentile])
    candidates = []
    if median > 0:
        candidates.append(spec.ae_target / median)
    if high > 0:
        candidates.append(spec.ae_highlight_level / high)
    return float(min(candidates)) if candidates else 1.0


def exposure_of(radiance: np.ndarray, spec: CameraModelSpec) -> float:
    """The exposure multiplier ``capture`` applies: auto or fixed, with the bias."""
    base = auto_exposure(radiance, spec) if spec.exposure == "auto" else float(spec.exposure)
    return base * 2.0 ** spec.exposure_bias_ev


def expose(radiance: np.ndarray, exposure: float) -> np.ndarray:
    """Scene radiance -> sensor level (1.0 = saturation), float32."""
    return np.multiply(radiance, np.float32(exposure), dtype=np.float32)


def white_balance(image: np.ndarray, gains_bgr) -> np.ndarray:
    """Per-channel gains (B, G, R)."""
    gains = np.asarray(gains_bgr, np.float32)
    return image if np.all(gains == 1) else image * gains


def lens_blur(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """A Gaussian blur of ``sigma_px`` pixels (the image unchanged at 0)."""
    if sigma_px <= 0:
        return image
    return cv2.GaussianBlur(image, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)


def motion_kernel(length_px: float, angle_deg: float) -> np.ndarray:
    """A normalised line kernel ``length_px`` long at ``angle_deg`` (anti-aliased by bilinear splatting)."""
    half = int(math.ceil(length_px / 2)) + 1
    kernel = np.zeros((2 * half + 1, 2 * half + 1), np.float64)
    n = max(2, int(math.ceil(length_px * 4)))
    s = np.linspace(-length_px / 2, length_px / 2, n)
    a = math.radians(angle_deg)
    xs, ys = half + s * math.cos(a), half + s * math.sin(a)
    x0, y0 = np.floor(xs).astype(int), np.floor(ys).astype(int)
    fx, fy = xs - x0, ys - y0
    for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(kernel, (y0 + dy, x0 + dx), w)
    return (kernel / kernel.sum()).astype(np.float32)


def motion_blur(image: np.ndarray, length_px: float, angle_deg: float) -> np.ndarray:
    """The image smeared along a line (the camera or the scene moving during the exposure)."""
    if length_px <= 0:
        return image
    return cv2.filter2D(image, -1, motion_kernel(length_px, angle_deg), borderType=cv2.BORDER_REFLECT)


def mosaic(image: np.ndarray, bayer: Bayer) -> np.ndarray:
    """The colour filter array: one channel per photosite, shape (H, W) (``none``: the image unchanged)."""
    if bayer == "none":
        return image
    out = np.empty(image.shape[:2], image.dtype)
    channels = _PATTERN_CHANNELS[bayer]
    for k, (r, c) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        out[r::2, c::2] = image[r::2, c::2, channels[k]]
    return out


def sensor(level: np.ndarray, spec: CameraModelSpec, rng: np.random.Generator) -> np.ndarray:
    """Photosite levels (1.0 = saturation) -> raw ADC values, uint16 0 .. 2**bit_depth - 1.

    Electrons are ``level * full_well`` (clipped at the full well) with shot noise (Poisson; its normal
    approximation above :data:`POISSON_BELOW` electrons) and Gaussian read noise; the ADC scales the full well
    to the top code, rounds and clips.
    """
    electrons = np.clip(level, 0.0, 1.0).astype(np.float32) * np.float32(spec.full_well)
    z = rng.standard_normal(electrons.shape, dtype=np.float32)
    read = np.float32(spec.read_noise)
    noisy = electrons + np.sqrt(electrons + read * read) * z  # shot + read noise, normal approximation
    dark = electrons < POISSON_BELOW
    if dark.any():
        mean = electrons[dark]
        noisy[dark] = rng.poisson(mean).astype(np.float32) + read * z[dark]
    top = (1 << spec.bit_depth) - 1
    codes = noisy * np.float32(top / spec.full_well)
    return np.clip(np.rint(codes), 0, top).astype(np.uint16)


def _bayer_code(bayer: Bayer, method: str) -> int:
    suffix = {"bilinear": "", "vng": "_VNG", "edge-aware": "_EA"}[method]
    return getattr(cv2, f"COLOR_Bayer{_OPENCV_BAYER[bayer]}2BGR{suffix}")


def demosaic(raw: np.ndarray, bayer: Bayer, method: str) -> np.ndarray:
    """Raw mosaic (H, W) -> BGR (H, W, 3), same dtype. VNG exists in OpenCV for 8-bit data only."""
    if bayer == "none":
        return raw
    return cv2.cvtColor(raw, _bayer_code(bayer, method))


def _hable(x: np.ndarray) -> np.ndarray:
    a, b, c, d, e, f = _HABLE
    return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f


@lru_cache(maxsize=16)
def tone_lut(tone: str, gamma: float, bit_depth: int) -> np.ndarray:
    """The tone curve as a table, raw code -> uint8 (0 -> 0, saturation -> 255, monotone)."""
    x = np.arange(1 << bit_depth, dtype=np.float64) / ((1 << bit_depth) - 1)
    if tone == "srgb":
        y = _srgb_encode(x)
    elif tone == "gamma":
        y = x ** (1.0 / gamma)
    else:  # filmic: Hable's toe and shoulder on linear, then the sRGB encoding
        y = _srgb_encode(_hable(x * FILMIC_WHITE) / _hable(np.array(FILMIC_WHITE)))
    lut = np.round(np.clip(y, 0, 1) * 255.0).astype(np.uint8)
    lut.setflags(write=False)
    return lut


def colour_matrix(saturation: float, hue_rotation_deg: float) -> np.ndarray:
    """The 3x3 matrix on 8-bit BGR values that scales the chroma (Cb, Cr) by ``saturation`` and rotates it by
    ``hue_rotation_deg`` (from Cb towards Cr), keeping the luma (BT.601)."""
    a = math.radians(hue_rotation_deg)
    c, s = saturation * math.cos(a), saturation * math.sin(a)
    chroma = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return np.linalg.inv(_YCBCR_FROM_BGR) @ chroma @ _YCBCR_FROM_BGR


def colour_adjust(image: np.ndarray, saturation: float, hue_rotation_deg: float) -> np.ndarray:
    """A camera's saturation and hue settings on the 8-bit BGR image (rounded and clipped to 0-255; the image
    itself at 1 and 0)."""
    if saturation == 1 and hue_rotation_deg == 0:
        return image
    return cv2.transform(image, colour_matrix(saturation, hue_rotation_deg))


def spec_record(spec: CameraModelSpec) -> dict[str, Any]:
    """The spec as a mapping for a manifest: every field, except the look fields at their (neutral) defaults
    (:data:`LOOK_FIELD_DEFAULTS`), so that a camera model without them is recorded as before they existed."""
    record = spec.model_dump(mode="json")
    for key, default in LOOK_FIELD_DEFAULTS.items():
        if record.get(key) == default:
            del record[key]
    return record


def encode(image: np.ndarray, jpeg_quality: int | None, chroma: str) -> tuple[bytes, str]:
    """JPEG (quality, chroma subsampling) or lossless PNG bytes, and the file suffix."""
    if jpeg_quality is None:
        ok, buf = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        suffix = ".png"
    else:
        sampling = cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420 if chroma == "420" else cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444
        ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality),
                                               cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling])
        suffix = ".jpg"
    if not ok:
        raise ValueError(f"OpenCV could not encode a {image.shape} image as {suffix}")
    return buf.tobytes(), suffix


def decode(encoded: bytes) -> np.ndarray:
    """The BGR uint8 image of encoded bytes."""
    return cv2.imdecode(np.frombuffer(encoded, np.uint8), cv2.IMREAD_COLOR)


def develop(raw: np.ndarray, spec: CameraModelSpec) -> np.ndarray:
    """Raw ADC values (mosaic, or (H, W, 3) without one) -> 8-bit BGR: demosaicing, the tone curve and the
    colour stage (saturation, hue).

    Bilinear and edge-aware demosaicing run on the linear raw values (as an ISP does); OpenCV's VNG takes 8-bit
    data only, so with it the tone curve maps the mosaic first and VNG interpolates the 8-bit values. A Blender
    view transform (a 3D LUT, not per photosite) takes the demosaiced levels; with VNG, the mosaic is sRGB-encoded
    to 8 bits, interpolated and decoded to linear levels first.
    """
    vng = spec.bayer != "none" and spec.demosaic == "vng"
    if spec.tone in VIEW_TONES:
        if vng:
            srgb = tone_lut("srgb", spec.gamma, spec.bit_depth)
            image = view_transform(linear_from_srgb(demosaic(srgb[raw], spec.bayer, "vng")), spec.tone)
        else:
            image = view_transform_codes(demosaic(raw, spec.bayer, spec.demosaic), spec.tone, spec.bit_depth)
    else:
        lut = tone_lut(spec.tone, spec.gamma, spec.bit_depth)
        image = demosaic(lut[raw], spec.bayer, "vng") if vng else lut[demosaic(raw, spec.bayer, spec.demosaic)]
    return colour_adjust(image, spec.saturation, spec.hue_rotation_deg)


def capture(radiance: np.ndarray, spec: CameraModelSpec, rng: np.random.Generator) -> Captured:
    """What the camera of ``spec`` streams for a linear-light BGR image ``radiance`` (float, (H, W, 3), any scale).

    Raises
    ------
    ValueError
        ``radiance`` is not an (H, W, 3) image or has non-finite values.
    """
    radiance = np.asarray(radiance, np.float32)
    if radiance.ndim != 3 or radiance.shape[2] != 3:
        raise ValueError(f"radiance must be an (H, W, 3) BGR image, got shape {radiance.shape}")
    if not np.isfinite(radiance).all():
        raise ValueError("radiance has non-finite values")
    level = expose(radiance, exposure_of(radiance, spec))
    level = white_balance(level, spec.white_balance)
    level = lens_blur(level, spec.lens_blur_px)
    level = motion_blur(level, spec.motion_blur_px, spec.motion_blur_angle_deg)
    raw = sensor(mosaic(level, spec.bayer), spec, rng)
    encoded, suffix = encode(develop(raw, spec), spec.jpeg_quality, spec.chroma)
    return Captured(decode(encoded), encoded, suffix)
