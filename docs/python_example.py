# %% [markdown]
# # volreel from Python: encode, open, look at a slice, measure
#
# A notebook-style script (each `# %%` is a cell; Jupyter and VS Code run them one by one). It
# runs as a whole too: `PYTHONPATH=build/python python3 docs/python_example.py [OUT_DIR]`.
# The test suite runs it.

# %%
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display needed; remove in a notebook
import matplotlib.pyplot as plt
import numpy as np

import volreel

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("volreel-example")
out.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# A small time-varying field: two Gaussian vortices drifting through a 64 x 48 x 32 box, with a
# little fine-scale structure. Frames are numpy arrays [z, y, x].

# %%
z, y, x = np.meshgrid(np.linspace(0, 1, 32), np.linspace(0, 1.5, 48), np.linspace(0, 2, 64),
                      indexing="ij")


def field(t):
    a = np.exp(-((x - 0.5 - 0.1 * t) ** 2 + (y - 0.7) ** 2 + (z - 0.5) ** 2) / 0.02)
    b = np.exp(-((x - 1.4 + 0.08 * t) ** 2 + (y - 0.8 - 0.05 * t) ** 2 + (z - 0.4) ** 2) / 0.05)
    ripple = 0.05 * np.sin(12 * x + t) * np.cos(9 * y - 0.5 * t) * np.sin(7 * z)
    return (a - 0.8 * b + ripple).astype(np.float32)


frames = np.stack([field(t) for t in range(8)])
print("frames", frames.shape, frames.dtype)

# %% [markdown]
# Encode to 50 dB (every frame's finest level at least that, over the sequence's value range).
# A generator of frames works as well as the stacked array.

# %%
summary = volreel.encode((f for f in frames), out / "vortices.vreel", psnr=50, overwrite=True)
print(f"encoded: {summary['bytes']} bytes, {summary['bps']:.3f} bps, "
      f"PSNR {summary['psnr']:.2f} dB")

# %%
c = volreel.open(out / "vortices.vreel")
print(c)
decoded = c[4]  # time step 4, finest level, [z, y, x]
coarse = c.frame(4, level=0)

# %% [markdown]
# A slice through the middle, original against decoded, and the error.

# %%
k = decoded.shape[0] // 2
fig, axes = plt.subplots(1, 3, figsize=(12, 3.2), constrained_layout=True)
for ax, image, title in zip(axes, [frames[4][k], decoded[k], decoded[k] - frames[4][k]],
                            ["original", "decoded", "decoded - original"]):
    if "-" in title:  # the error, on limits symmetric about 0
        limit = np.abs(image).max()
        im = ax.imshow(image, origin="lower", cmap="RdBu_r", vmin=-limit, vmax=limit)
    else:
        im = ax.imshow(image, origin="lower", cmap="viridis")
    ax.set_title(f"{title}, z = {k}")
    fig.colorbar(im, ax=ax, shrink=0.8)
fig.savefig(out / "slice.png", dpi=80)

# %% [markdown]
# PSNR and SSIM as `volreel compare` defines them (range of the original).

# %%
psnr = volreel.psnr(frames[4], decoded)
ssim = volreel.ssim(frames[4], decoded)
print(f"time step 4: PSNR {psnr:.2f} dB, SSIM {ssim:.5f}; coarsest level {coarse.shape}")
