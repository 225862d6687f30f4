// auto_transfer.hpp: a transfer function chosen from the data — for signed fields with heavy
// tails such as turbulence pressure, whose bulk fills the middle of the value range while the
// structures of interest (low-pressure vortex cores, high-pressure stagnation regions) are the
// rare extremes. Colour and opacity are placed at quantiles of the decoded values, so the bulk
// is clear whatever the range: the lowest 4 % blue rising to opaque, the highest 4 % orange to red,
// a tail that is only the bulk's edge faded out and the opacity bounded so that the average ray
// through the volume keeps some transmittance (TransferFunction::from_quantiles).
#pragma once

#include <cstddef>
#include <string>

#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/format/container.hpp"

namespace volreel::loop {

/// Quantiles of the values of up to `max_bricks` finest-level bricks (evenly spread) of the
/// middle frame (on a local disk, where that one is damaged, the first readable of the two beside
/// it; over HTTP, whose failures would repeat, the middle frame alone), decoded on the CPU; the
/// transfer function spans the manifest's value range. "cool-warm" when none of them is readable.
cpu_render::TransferFunction quantile_transfer(const format::Container& container,
                                               std::size_t max_bricks = 64);

/// A transfer function named on a command line: "auto" (quantile_transfer), a preset name
/// (TransferFunction::preset_names(), over the manifest's value range) or a JSON file
/// (transfer_function.hpp's format). Throws InputError naming the option and the problem.
cpu_render::TransferFunction transfer_from_spec(const std::string& spec,
                                                const format::Container& container,
                                                const std::string& option = "--transfer");

}  // namespace volreel::loop
