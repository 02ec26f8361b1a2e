"""Alpha textures: loading the coverage channel of an image file through Pillow.

An ``AlphaTexture`` keeps the raw integer values and the format's maximum, so 8- and 16-bit
sources compare against thresholds exactly (``alpha8`` is in 8-bit units either way).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from PIL import Image, UnidentifiedImageError

from . import checks
from .errors import InputError, InputTypeError

# Extensions we look for when a folder is given (Pillow decides what it can actually read).
IMAGE_EXTENSIONS = (".png", ".tga", ".jpg", ".jpeg", ".bmp", ".dds", ".tif", ".tiff", ".webp", ".gif")


@dataclass(frozen=True)
class AlphaTexture:
    """Coverage values of one texture: ``values[y, x]``, row 0 is the first image row (v = 0)."""

    name: str
    values: np.ndarray  # uint8 / uint16 raw values, or float64 in [0, 1] (maxval 1); shape (H, W)
    maxval: int

    def __post_init__(self) -> None:
        checks.text(self.name, "name")
        if not isinstance(self.values, np.ndarray) or self.values.dtype.kind not in "uif":
            raise InputTypeError(f"values must be a numpy array of integers or floats, got "
                                 f"{checks._show(self.values)}", self.name, param="values")
        checks.number(self.maxval, "maxval", 0, open_lo=True)
        v = self.values
        if v.ndim != 2:
            raise InputError(f"alpha must be a 2-D array, got shape {v.shape}", self.name)
        if v.shape[0] == 0 or v.shape[1] == 0:
            raise InputError(f"empty image ({v.shape[1]}x{v.shape[0]})", self.name)
        if self.maxval <= 0:
            raise InputError(f"bad maximum value {self.maxval}", self.name)

    @property
    def width(self) -> int:
        return int(self.values.shape[1])

    @property
    def height(self) -> int:
        return int(self.values.shape[0])

    @property
    def alpha8(self) -> np.ndarray:
        """Alpha in 8-bit units (0..255) as float64; exact for 8-bit sources and for 16-bit
        values that are multiples of 257 (multiply before dividing keeps integers integral)."""
        return self.values.astype(np.float64) * 255.0 / self.maxval

    @classmethod
    def from_array(cls, name: str, alpha: object, channel: str | int | None = None) -> "AlphaTexture":
        """Wrap an array as a numpy user holds a texture.

        Parameters
        ----------
        name : str
            The name reported in errors and results.
        alpha : array_like
            ``(H, W)`` coverage, or ``(H, W, C)`` pixels with C = 1 (L), 2 (LA), 3 (RGB) or
            4 (RGBA), the bands read as an image file's are: the alpha of LA / RGBA, the one
            channel of L; RGB has no alpha and needs ``channel``. Integers are 8-bit (16-bit if any
            value exceeds 255); floats must lie in [0, 1] and are kept exactly (``maxval`` 1).
        channel : str or int, optional
            A band name (R, G, B, A, L) or index, to read coverage from another channel.

        Returns
        -------
        AlphaTexture

        Raises
        ------
        InputTypeError, InputError
            ``alpha`` not a numeric array, a bad shape or range, or no such ``channel``.

        Examples
        --------
        >>> import numpy as np
        >>> rgba = np.zeros((2, 2, 4), np.uint8); rgba[..., 3] = [[0, 255], [128, 64]]
        >>> AlphaTexture.from_array("leaf", rgba).values.tolist()
        [[0, 255], [128, 64]]
        >>> AlphaTexture.from_array("half", np.full((1, 1), 0.5)).alpha8.tolist()
        [[127.5]]
        """
        checks.text(name, "name")
        _check_channel(channel)
        a = checks.array(alpha, "alpha", kinds="biuf")
        if a.ndim == 3:
            band_text = ARRAY_BANDS.get(a.shape[2])
            if band_text is None:
                raise InputError(f"an (H, W, C) texture needs 1 to 4 channels, got shape {a.shape}", name)
            bands = tuple(band_text)
            what = f"an {''.join(bands)} array"
            a = a[:, :, _coverage_band(bands, channel, what, f"{what} has no alpha channel; give {{channel}} to pick one", name)]
        elif channel is not None and a.ndim == 2:
            try:
                _channel_index(channel, ("L",))
            except KeyError:
                raise InputError(f"no channel {channel!r} in a single-channel (H, W) array", name) from None
        if a.ndim != 2:
            raise InputError(f"a texture array must be (H, W) or (H, W, C), got shape {a.shape}", name)
        if a.dtype.kind == "f":
            if not np.all(np.isfinite(a)) or a.min(initial=0) < 0 or a.max(initial=0) > 1:
                raise InputError("float alpha must be finite and in [0, 1]", name)
            return cls(name, np.ascontiguousarray(a, dtype=np.float64), 1)
        if a.dtype.kind == "b":
            return cls(name, np.ascontiguousarray(a, dtype=np.uint8) * np.uint8(255), 255)
        if a.dtype.kind not in "ui":
            raise InputError(f"unsupported alpha dtype {a.dtype}", name)
        if a.size and a.min() < 0:
            raise InputError("negative alpha values", name)
        maxval = 255 if (a.size == 0 or a.max() <= 255) else 65535
        if a.size and a.max() > 65535:
            raise InputError("integer alpha above 65535", name)
        return cls(name, np.ascontiguousarray(a, dtype=np.uint8 if maxval == 255 else np.uint16), maxval)

    @property
    def is_float(self) -> bool:
        """True for float coverage in [0, 1] (kept exactly; ``maxval`` is 1)."""
        return self.values.dtype.kind == "f"


# the bands of an (H, W, C) array, as an image file with C channels has them
ARRAY_BANDS = {1: "L", 2: "LA", 3: "RGB", 4: "RGBA"}


def as_texture(texture: object, name: str = "array", channel: str | int | None = None) -> AlphaTexture:
    """What every function taking a texture accepts: an ``AlphaTexture`` (returned as it is), a
    numpy array (``AlphaTexture.from_array``) or an image file's path (``load_alpha``).

    Examples
    --------
    >>> import numpy as np
    >>> as_texture(np.array([[0, 65535]], np.uint16)).maxval
    65535
    """
    checks.text(name, "name")
    _check_channel(channel)
    if isinstance(texture, AlphaTexture):
        if channel is not None:
            raise InputError("channel applies to arrays and files, not to an AlphaTexture", texture.name,
                             param="channel")
        return texture
    if isinstance(texture, (str, os.PathLike)):
        return load_alpha(texture, channel)
    if isinstance(texture, (np.ndarray, list, tuple)):
        return AlphaTexture.from_array(name, texture, channel)
    raise InputTypeError(f"texture must be an AlphaTexture, a numpy array or an image path, got "
                         f"{checks._show(texture)}", param="texture")


def _check_channel(channel: object) -> None:
    """A ``channel`` argument: None, a band name or an index."""
    if channel is not None and (isinstance(channel, bool) or not isinstance(channel, (str, int, np.integer))):
        raise InputTypeError(f"channel must be a band name (R, G, B, A, L) or an index, got {checks._show(channel)}",
                             param="channel")


def _channel_index(channel, bands) -> int:
    if isinstance(channel, (int, np.integer)) or (isinstance(channel, str) and channel.isdigit()):
        idx = int(channel)
    else:
        key = str(channel).upper()
        if key not in bands:
            raise KeyError(key)
        idx = bands.index(key)
    if not 0 <= idx < len(bands):
        raise KeyError(channel)
    return idx


def _coverage_band(bands, channel, what: str, no_alpha: str, name: str) -> int:
    """The band coverage is read from, of an image or array with ``bands`` (e.g. ("R", "G", "B",
    "A")): ``channel`` if given, else the alpha band, else the one band of a mask; an RGB source
    has no coverage of its own (the error ``no_alpha``). ``what`` names the source in errors."""
    if channel is not None:
        try:
            return _channel_index(channel, bands)
        except KeyError:
            raise InputError(f"no channel {channel!r} in {what}", name) from None
    if "A" in bands:
        return bands.index("A")
    if len(bands) == 1:
        return 0  # a single-channel mask
    raise InputError(no_alpha, name, param="channel")


def _mode_maxval(im: Image.Image) -> int:
    if im.mode.startswith("I;16") or im.mode == "I":
        return 65535
    return 255


def load_alpha(path: str | os.PathLike[str] | np.ndarray, channel: str | int | None = None,
               name: str = "array") -> AlphaTexture:
    """Load the coverage of an image file, or wrap an array (``AlphaTexture.from_array``: (H, W)
    or (H, W, C) greyscale, LA, RGB or RGBA; uint8, uint16, bool or float in [0, 1]).

    ``channel=None``: the alpha of RGBA / LA / PA, of P with a tRNS transparency, or the single
    channel of a greyscale mask (L, I;16). An image with colour but no alpha is an error.
    ``channel``: a band name (R, G, B, A, L) or index, to read coverage from another channel.
    ``name``: an array's name in messages and results (a file's is its base name).

    Raises an ``InputTypeError`` for an argument of the wrong type, an ``InputError`` naming the
    file for one that does not exist or cannot be read, or has no such channel.

    Example::

        >>> import numpy as np
        >>> from omaps.texture import load_alpha
        >>> load_alpha(np.array([[0, 255]], np.uint8)).alpha8.tolist()
        [[0.0, 255.0]]
    """
    _check_channel(channel)
    if isinstance(path, np.ndarray):
        return AlphaTexture.from_array(name, path, channel)
    path = checks.path(path, "path")
    name = os.path.basename(path)
    if not os.path.exists(path):
        raise InputError("no such file", path)
    if os.path.isdir(path):
        raise InputError("is a folder, not an image", path)
    with open_image(path, path) as im:
        return _alpha_from_image(im, name, path, channel)


def open_image(source, path) -> Image.Image:
    """Open and decode an image through Pillow: ``source`` a file name or a binary file object,
    ``path`` the name to report. The one boundary where Pillow's many exception types on corrupt
    or hostile data (OSError, SyntaxError, struct.error, NotImplementedError, EOFError,
    DecompressionBombError, ...) become an ``InputError`` naming the file, with Pillow's message.
    The returned image is loaded; close it (it is a context manager)."""
    try:
        im = Image.open(source)
    except UnidentifiedImageError:
        raise InputError("not an image Pillow can read", path) from None
    except Exception as exc:  # the third-party decode boundary, message kept
        raise InputError(f"cannot decode image ({type(exc).__name__}: {exc})", path) from None
    try:
        im.load()
        if im.width <= 0 or im.height <= 0:
            raise InputError(f"empty image ({im.width}x{im.height})", path)
        return im
    except InputError:
        im.close()
        raise
    except Exception as exc:  # as above: truncated data, bad chunks, unsupported variants
        im.close()
        raise InputError(f"cannot decode image ({type(exc).__name__}: {exc})", path) from None


def _alpha_from_image(im: Image.Image, name: str, path: str, channel) -> AlphaTexture:
    if im.width == 0 or im.height == 0:
        raise InputError(f"empty image ({im.width}x{im.height})", path)
    mode = im.mode
    if mode == "P" or mode == "PA":
        im = im.convert("RGBA")  # applies tRNS / palette alpha
        mode = "RGBA"
        if channel is None and np.all(np.asarray(im.getchannel("A")) == 255):
            raise InputError("palette image without transparency (tRNS); give {channel} to pick a band", path,
                             param="channel")
    elif mode == "1":
        im = im.convert("L")
        mode = "L"
    elif mode in ("RGBa", "La"):
        im = im.convert(mode[:-1] + "A")
        mode = im.mode
    elif mode == "F":
        raise InputError("32-bit float images are not supported; save the mask as 8 or 16 bit", path)

    maxval = _mode_maxval(im)
    bands = im.getbands()
    idx = _coverage_band(bands, channel, f"a {im.mode} image (bands {''.join(bands)})",
                         f"image has no alpha channel (mode {im.mode}); give {{channel}} to pick one", path)
    if len(bands) == 1:
        arr = np.asarray(im)
    else:
        arr = np.asarray(im.getchannel(idx))
    if arr.dtype.kind == "i":  # mode I holds 16-bit data in int32
        if arr.size and (arr.min() < 0 or arr.max() > 65535):
            raise InputError("32-bit integer image with values outside 0..65535", path)
        arr = arr.astype(np.uint16)
    elif arr.dtype.kind == "b":
        arr = arr.astype(np.uint8) * 255
    if arr.dtype.byteorder == ">":
        arr = arr.astype(arr.dtype.newbyteorder("="))
    return AlphaTexture(name, np.ascontiguousarray(arr), maxval)


def find_images(paths) -> tuple[list[str], list[str]]:
    """Expand files and folders (recursively, sorted) into image files.

    Returns (images, skipped): files named explicitly are always returned (so a bad one is
    reported); files in folders without an image extension are listed in ``skipped``.
    """
    images: list[str] = []
    skipped: list[str] = []
    for p in paths:
        p = os.fspath(p)
        if os.path.isdir(p):
            for root, dirs, files in os.walk(p):
                dirs.sort()
                for f in sorted(files):
                    full = os.path.join(root, f)
                    (images if f.lower().endswith(IMAGE_EXTENSIONS) else skipped).append(full)
        elif os.path.exists(p):
            images.append(p)
        else:
            raise InputError("no such file or folder", p)
    return images, skipped


def without_alpha(path) -> str | None:
    """Why an image found in a folder is not an alpha mask, from its header alone (nothing is
    decoded): it has no alpha channel, so reading it without a channel given would fail (RGB
    photographs and screenshots, normal maps, a palette without transparency). None for an image
    with one (or a single band, read as coverage), and for a file Pillow cannot open (reading it
    reports that)."""
    try:
        with Image.open(path) as im:
            mode, bands, info = im.mode, im.getbands(), im.info
    except Exception:  # (not readable: the read that follows says why)
        return None
    if mode == "P":
        return None if "transparency" in info else "palette image without transparency"
    if len(bands) == 1 or "A" in bands or "a" in bands or mode == "PA":
        return None
    return f"no alpha channel, mode {mode}"
