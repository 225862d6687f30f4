// coding_settings.hpp: how the encoder codes bricks — the codec, variable or fixed rate and the
// rule that spends atoms, the pursuit, the quantization of block means and coefficients.
// docs/benchmarks.md has the measurements behind the defaults.
#pragma once

#include <string>

#include "volreel/datasets/volume.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::encoder {

/// Smax where no option sets it: one atom per value of a block, so that no ε is out of reach (the
/// rule stops each block's pursuit long before, except on noise-like blocks at small ε).
inline constexpr int default_max_atoms = 216;

/// How variable rate chooses the number of atoms of each block (both driven by ε).
enum class VariableRateRule {
  /// Rate-distortion optimal (Lagrangian): add the next atom while it lowers the block's squared
  /// error by at least lagrangian_factor·m·ε² (m = 216 values). Every code costs the same 16 bits,
  /// so this gives every block the same distortion-per-bit slope, which minimises the total
  /// squared error (hence maximises PSNR) for the total size: smooth blocks get few atoms, rough
  /// blocks many.
  lagrangian,
  /// Add atoms until the block's RMS error is at most ε (equal error per block; the paper's rule).
  tolerance,
};

/// The names volreel uses for a rule (command lines, manifests): "lagrangian" and "tolerance".
const char* rate_rule_name(VariableRateRule rule);
/// The inverse; throws InputError naming --rate-rule and the value on another name.
VariableRateRule rate_rule_from_name(const std::string& name);

/// The names of the codecs (command lines, manifest comparisons): "ksvd" and "zfp".
const char* codec_name(format::Codec codec);
/// The inverse; throws InputError naming --codec and the value on another name.
format::Codec codec_from_name(const std::string& name);

/// CodingSettings::mean_bits from its command-line text: "auto" (-1) or a whole number 0..15;
/// throws InputError naming --mean-bits and the text otherwise.
int mean_bits_from_text(const std::string& text);
/// CodingSettings::coef_bits from its command-line text: "auto" (-1) or a whole number 1..16;
/// throws InputError naming --coef-bits and the text otherwise.
int coef_bits_from_text(const std::string& text);
/// CodingSettings::brick_size from its command-line text: "auto" (0: chosen per volume,
/// format::choose_brick_shape) or a multiple of 6 in 12..66; throws InputError naming
/// --brick-size and the text otherwise.
std::uint32_t brick_size_from_text(const std::string& text);

/// How bricks are coded.
struct CodingSettings {
  format::Codec codec = format::Codec::ksvd;
  /// The container the frames belong to (format::container_identifier), written into every
  /// frame header; 0 for frames of no container (trials of the rate search, benchmarks).
  std::uint64_t container_id = 0;
  /// Stored voxels per brick axis (format::BrickShape::size: a multiple of 6 in 12..66); the
  /// encoder's callers choose it per volume (format::choose_brick_shape).
  std::uint32_t brick_size = format::default_brick_size;
  double tolerance = 0;  ///< ksvd variable rate: ε (data units), see VariableRateRule
  VariableRateRule rule = VariableRateRule::lagrangian;
  /// Lagrangian rule: the minimum gain of an atom, as a fraction of m·ε² (> 0). Only its ratio
  /// to coef_step_factor² and the product with ε² matter: chosen with coef_step_factor on the
  /// rate-distortion suite (docs/benchmarks.md). The PSNR delivered at ε then lies some dB below
  /// 20·log10(range/ε) (about 5 dB on the suite's turbulence), so --psnr measures each frame and
  /// codes it again at a smaller ε where it falls short.
  double lagrangian_factor = 0.25;
  /// Lagrangian rule: weigh each block's atom gains by the share of its voxels that the decoder
  /// takes from it (its brick's interior, inside the level). The rest are the apron, a copy of a
  /// neighbour's interior coded there, and padding outside the volume: a block with a few own
  /// voxels weighs at least as one voxel (1/216), so it gets atoms only where they are 216 times
  /// cheaper, and a block of padding alone weighs 0 and keeps its mean only, or is not stored
  /// past the payload's box of coded blocks (format::coded_box) (on the non-cube
  /// member of the rate-distortion suite, +0.3 to +3 dB at equal bps above 0.7 bps).
  bool weight_owned_voxels = true;
  /// Lagrangian rule: the levels above the finest are coded to ε·F^d, d levels up (their atom
  /// gains weigh 1/F^(2d), their means' step grows by F^d). A coarse level is drawn only where its
  /// voxels, 2^d times as wide, are too small on screen for the finer one to matter, and it already
  /// differs from the full-resolution data by its downsampling, by several ε. At F = 2 the coding
  /// error grows with that difference and stays below it, the coarse levels take a smaller share
  /// of the bytes (the finest level unchanged), and smaller coarse bricks arrive sooner on slow
  /// links. 1: every level to ε. On a self-similar field the downsampling difference keeps
  /// doubling per level. The ε rule and fixed rate ignore it.
  double level_tolerance_factor = 2.0;
  /// Lagrangian rule: a brick above the finest level is also coded to r·δ where that is coarser
  /// than ε·F^d, δ being the RMS difference between the frame and the brick's own voxels (what
  /// its downsampling lost, PyramidWindow::brick_detail). Its drawing then differs from the
  /// frame by at most sqrt(1 + r²)·δ, 10·log10(1 + r²) dB more than its downsampling alone
  /// (0.97 dB at 0.5), while at small ε the coarse levels stop taking bits the finest level
  /// could use. 0: ε·F^d alone.
  double level_detail_ratio = 0.5;
  /// Whether the coarse levels are coded by what they lost (ksvd variable rate, Lagrangian rule,
  /// level_detail_ratio > 0): the pyramid then computes each coarse voxel's detail.
  bool uses_level_detail() const {
    return codec == format::Codec::ksvd && fixed_sparsity == 0 &&
           rule == VariableRateRule::lagrangian && level_detail_ratio > 0;
  }
  int fixed_sparsity =
      0;  ///< ksvd fixed rate: exactly min(S, needed) atoms per block (0: variable)
  /// Smax ≤ 216, one atom per value of a block. The dictionary spans every block (its DCT part), so
  /// a block needs more atoms only for more quality: the rule, not Smax, stops the pursuit.
  int max_atoms = default_max_atoms;
  /// ksvd: which atom each pursuit step adds (both rates). ORMP (the atom that lowers the block's
  /// squared error most) needs fewer atoms than OMP (the most correlated one) for the same error;
  /// see dictionary::AtomSelection.
  dictionary::AtomSelection selection = dictionary::AtomSelection::error;
  /// ksvd: the bits b of each brick's quantized block means (format/SPEC.md, the layout word). -1:
  /// variable rate gives each brick the fewest bits (0..15) whose step over the span of its block
  /// means is at most mean_step_factor·ε_l (ε_l: the brick's level's tolerance, see
  /// level_tolerance_factor), fixed rate (no ε) 12 bits; 0..15: every brick exactly b bits.
  int mean_bits = -1;
  /// The mean step as a fraction of ε. A mean off by e adds 216·e² to its block's squared error,
  /// so halving the step gains 13.5·step² for one more bit per block; the Lagrangian rule buys
  /// 0.25·216·ε² per code (16 bits when this was measured, format 2), and the two slopes are equal
  /// at a step of ε/2: of the factors measured, 0.5 gives the most PSNR for the same bytes.
  double mean_step_factor = 0.5;
  /// ksvd: the magnitude bits c of each brick's quantized coefficients (format/SPEC.md, the layout
  /// word). -1: variable rate quantizes with the step coef_step_factor·ε_l, fixed rate with the
  /// brick's largest coefficient / 128; 1..16: every brick with its largest coefficient / 2^c.
  int coef_bits = -1;
  /// The coefficient step as a multiple of ε (see coef_bits). A coefficient off by e adds e² to
  /// its block's squared error (atoms have unit norm), against the m·ε² scale of the block's
  /// coding error. Chosen on the rate-distortion suite (scripts/rd-suite; docs/benchmarks.md,
  /// "Coefficient step"): with Rice-coded magnitudes 11 leads at equal bps where 4 and 8 lead less
  /// (a coarser step loses more to quantization, measured against the unquantized codes).
  double coef_step_factor = 11.0;
  /// > 0: the pointwise bound E (data units): every decoded value of a coded block within E of
  /// the original, checked after quantization; blocks take atoms (and bricks a finer coefficient
  /// step) until it holds (volreel encode --max-error).
  double max_error = 0;
  double zfp_accuracy = 0;  ///< zfp fixed-accuracy tolerance (data units)
  /// Quantize coefficients one at a time, re-solving the least-squares fit of the block's later
  /// coefficients against the error of the ones already quantized ("quantize inside the pursuit").
  bool refit_quantization = true;
  /// Variable rate, ε rule: while a block's quantized error exceeds ε, add the atom most correlated
  /// with the quantized residual (up to Smax) and quantize again ("quantization inside the
  /// pursuit"). Off by default: it recovers part of the quantization loss for more bytes (about
  /// neutral at equal bps) and slows the encoding.
  bool extend_pursuit = false;
  /// Variable rate with a learned dictionary that ends with the DCT basis: code each brick also
  /// with the basis alone (its atoms indexed from the band split, format/SPEC.md, "split flag")
  /// and keep the coding of the lower cost (fewer blocks over --max-error, then squared error plus
  /// lagrangian_factor·m·ε² per code's worth of bytes), so that the learned atoms are used only in
  /// the bricks where they pay. Off at fixed rate.
  bool split_bricks = true;
  /// With split_bricks in effect: false skips the whole dictionary's pursuit and codes every
  /// brick with the basis alone (split flag set), as the comparison would where the basis wins in
  /// every brick — the same payloads then, for a fraction of the time. encode sets it false where
  /// the rate search found the learned atoms kept in none of its sample's bricks at the ε it chose
  /// (RateSearch::learned_bricks).
  bool learned_pursuit = true;
  double value_min = 0, value_max = 0;  ///< the sequence's value range, for node histograms
};

}  // namespace volreel::encoder
