#!/usr/bin/python3
"""skimage_check.py: checks `volreel compare` against scikit-image's PSNR and SSIM.

Usage: /usr/bin/python3 tests/skimage_check.py <path-to-volreel>

Makes test images deterministically with numpy (gray, RGB, RGBA; gradients, noise, blurred and
shifted copies; sizes that are not multiples of 8), writes them as PNG, runs
`volreel compare a.png b.png --json` and compares "psnr" and "ssim" with
skimage.metrics.peak_signal_noise_ratio(data_range=255) and structural_similarity(channel_axis=2,
gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=255). Then does the same
for 3D float32 volumes (`--dims XxYxZ`, x fastest), whose reference is the float64 SSIM with
data_range = max - min of the original and PSNR = 10*log10(range^2 / MSE).
Exits 1 unless every value agrees within 1e-3.
"""

import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import scipy.ndimage as ndi
import skimage
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

try:
    from PIL import Image as PILImage
except ImportError:  # Debian's python3-skimage brings imageio if not Pillow
    PILImage = None
    import imageio

TOLERANCE = 1e-3


def save_png(path, array):
    """Writes a uint8 (or uint16 gray) array as PNG; shape (h, w) or (h, w, channels)."""
    if PILImage is not None:
        PILImage.fromarray(array).save(path)
    else:
        imageio.imwrite(path, array)


def run_compare(volreel, args):
    """Runs `volreel compare ARGS --json` and returns the parsed JSON object."""
    command = [volreel, "compare", *args, "--json"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=120)
    if result.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited with {result.returncode}:\n"
                           f"{result.stdout}{result.stderr}")
    text = result.stdout
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        start = text.find("{")  # tolerate a line of progress before the JSON
        if start < 0:
            raise RuntimeError(f"{' '.join(command)} printed no JSON object:\n{text}")
        return json.JSONDecoder().raw_decode(text[start:])[0]


def as_number(value):
    """JSON number, or None / "inf" spellings of infinity, as a float."""
    if value is None:
        return math.inf  # nlohmann::json writes +inf as null
    if isinstance(value, str):
        return float(value)
    return float(value)


def agree(ours, reference):
    if math.isinf(reference):
        return math.isinf(ours) and ours > 0
    return math.isfinite(ours) and abs(ours - reference) <= TOLERANCE


class Checker:
    def __init__(self):
        self.failures = []

    def check(self, name, metric, ours, reference):
        ok = agree(ours, reference)
        print(f"  {'ok  ' if ok else 'FAIL'} {name:32s} {metric:5s} volreel {ours:.9f}  "
              f"reference {reference:.9f}  difference {ours - reference if math.isfinite(reference) else 0:.2e}")
        if not ok:
            self.failures.append(f"{name}: {metric} volreel {ours!r} vs skimage {reference!r}")


# -------------------------------------------------------------------------------------------------
# Test data, all from fixed seeds.

def gradient(height, width):
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    return 40 + 170 * (x / (width - 1)) * 0.6 + 60 * np.sin(y / 7.0) * np.cos(x / 11.0)


def to_uint8(values):
    return np.clip(np.rint(values), 0, 255).astype(np.uint8)


def image_pairs(rng):
    """(name, original uint8, decoded uint8) for gray, RGB and RGBA images."""
    h, w = 45, 67
    gray = gradient(h, w)
    pairs = [
        ("gray gradient + noise", to_uint8(gray), to_uint8(gray + rng.normal(0, 10, gray.shape))),
        ("gray gradient blurred", to_uint8(gray), to_uint8(ndi.gaussian_filter(gray, 1.2))),
        ("gray identical", to_uint8(gray), to_uint8(gray)),
    ]
    noise = rng.uniform(0, 255, (h, w))
    pairs.append(("gray noise + noise", to_uint8(noise), to_uint8(noise + rng.normal(0, 25, noise.shape))))

    rgb = np.stack([gradient(h, w), 255 - gradient(h, w), 128 + 60 * rng.standard_normal((h, w))], axis=2)
    rgb_shifted = np.roll(rgb, shift=(1, 2), axis=(0, 1))
    pairs.append(("rgb shifted by (1, 2)", to_uint8(rgb), to_uint8(rgb_shifted)))
    pairs.append(("rgb blurred", to_uint8(rgb), to_uint8(ndi.gaussian_filter(rgb, (1.0, 1.0, 0)))))
    pairs.append(("rgb + noise", to_uint8(rgb), to_uint8(rgb + rng.normal(0, 5, rgb.shape))))

    h4, w4 = 61, 53
    rgba = np.concatenate([np.stack([gradient(h4, w4)] * 3, axis=2) + rng.normal(0, 20, (h4, w4, 3)),
                           np.full((h4, w4, 1), 200.0) + 40 * np.sin(np.arange(w4) / 5.0)[None, :, None]],
                          axis=2)
    pairs.append(("rgba + noise", to_uint8(rgba), to_uint8(rgba + rng.normal(0, 8, rgba.shape))))
    return pairs


def check_images(volreel, directory, rng, checker):
    print("images (PSNR and SSIM, data range 255):")
    for index, (name, original, decoded) in enumerate(image_pairs(rng)):
        a_path, b_path = directory / f"a{index}.png", directory / f"b{index}.png"
        save_png(a_path, original)
        save_png(b_path, decoded)
        result = run_compare(volreel, [str(a_path), str(b_path)])
        # volreel leaves an alpha channel (of gray + alpha or RGBA) out.
        if original.ndim == 3 and original.shape[2] in (2, 4):
            original, decoded = original[..., :-1], decoded[..., :-1]
            if original.shape[2] == 1:
                original, decoded = original[..., 0], decoded[..., 0]
        channel_axis = 2 if original.ndim == 3 else None
        ssim = structural_similarity(original, decoded, channel_axis=channel_axis, gaussian_weights=True,
                                     sigma=1.5, use_sample_covariance=False, data_range=255)
        if np.array_equal(original, decoded):
            psnr = math.inf
        else:
            psnr = peak_signal_noise_ratio(original, decoded, data_range=255)
        label = f"{name} {original.shape[1]}x{original.shape[0]}"
        checker.check(label, "psnr", as_number(result["psnr"]), psnr)
        checker.check(label, "ssim", as_number(result["ssim"]), ssim)


def check_conversions(volreel, directory, rng, checker):
    """PNGs that volreel converts on reading: a palette image and a 16-bit gray image, each
    compared with its 8-bit RGB / gray equivalent, must be identical (SSIM 1, PSNR infinite)."""
    if PILImage is None:
        print("conversions: skipped (Pillow not available to write palette and 16-bit PNGs)")
        return
    print("PNG conversions (must be identical to the 8-bit equivalent):")
    h, w = 45, 67
    rgb = to_uint8(np.stack([gradient(h, w), 255 - gradient(h, w), rng.uniform(0, 255, (h, w))], axis=2))
    palette = PILImage.fromarray(rgb).convert("P", palette=PILImage.ADAPTIVE, colors=64)
    palette.save(directory / "palette.png")
    save_png(directory / "palette_rgb.png", np.asarray(palette.convert("RGB")))
    gray8 = to_uint8(gradient(h, w))
    save_png(directory / "gray16.png", gray8.astype(np.uint16) * 257)
    save_png(directory / "gray8.png", gray8)
    for name, a, b in [("palette vs RGB", "palette.png", "palette_rgb.png"),
                       ("16-bit vs 8-bit gray", "gray16.png", "gray8.png")]:
        result = run_compare(volreel, [str(directory / a), str(directory / b)])
        checker.check(name, "psnr", as_number(result["psnr"]), math.inf)
        checker.check(name, "ssim", as_number(result["ssim"]), 1.0)


def check_volumes(volreel, directory, rng, checker):
    print("3D volumes (float32, x fastest):")
    nx, ny, nz = 40, 36, 33
    z, y, x = np.mgrid[0:nz, 0:ny, 0:nx].astype(np.float64)
    field = np.sin(x / 4.0) * np.cos(y / 6.0) + 0.5 * np.sin(z / 5.0 + x / 9.0) + 0.1 * rng.standard_normal(x.shape)
    original = field.astype(np.float32)
    pairs = [
        ("volume + noise", original, (field + 0.05 * rng.standard_normal(x.shape)).astype(np.float32)),
        ("volume blurred", original, ndi.gaussian_filter(field, 0.8).astype(np.float32)),
        ("volume quantized", original, (np.round(field * 8) / 8).astype(np.float32)),
    ]
    for index, (name, a, b) in enumerate(pairs):
        a_path, b_path = directory / f"a{index}.f32", directory / f"b{index}.f32"
        a.tofile(a_path)  # numpy shape (z, y, x), C order: x fastest
        b.tofile(b_path)
        result = run_compare(volreel, [str(a_path), str(b_path), "--dims", f"{nx}x{ny}x{nz}"])
        frames = result["frames"]
        if len(frames) != 1:
            checker.failures.append(f"{name}: expected 1 frame in the JSON, got {len(frames)}")
            continue
        a64, b64 = a.astype(np.float64), b.astype(np.float64)
        data_range = float(a64.max()) - float(a64.min())
        ssim = structural_similarity(a64, b64, data_range=data_range, gaussian_weights=True, sigma=1.5,
                                     use_sample_covariance=False)
        psnr = 10 * math.log10(data_range ** 2 / float(np.mean((a64 - b64) ** 2)))
        label = f"{name} {nx}x{ny}x{nz}"
        checker.check(label, "psnr", as_number(frames[0]["psnr"]), psnr)
        checker.check(label, "ssim", as_number(frames[0]["ssim"]), ssim)


def main():
    if len(sys.argv) != 2:
        print("usage: skimage_check.py <path-to-volreel>", file=sys.stderr)
        return 2
    volreel = sys.argv[1]
    print(f"scikit-image {skimage.__version__}, numpy {np.__version__}, volreel {volreel}")
    checker = Checker()
    rng = np.random.default_rng(20240611)
    with tempfile.TemporaryDirectory(prefix="volreel_skimage_") as name:
        directory = Path(name)
        try:
            check_images(volreel, directory, rng, checker)
            check_conversions(volreel, directory, rng, checker)
            check_volumes(volreel, directory, rng, checker)
        except (RuntimeError, KeyError, TypeError, ValueError, subprocess.TimeoutExpired) as error:
            print(f"FAILED: {type(error).__name__}: {error}", file=sys.stderr)
            return 1
    if checker.failures:
        print(f"FAILED: {len(checker.failures)} value(s) differ from scikit-image by more than {TOLERANCE}:",
              file=sys.stderr)
        for failure in checker.failures:
            print(f"  {failure}", file=sys.stderr)
        return 1
    print(f"all values agree with scikit-image within {TOLERANCE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
