// panels.cpp: the player's Dear ImGui panels — the HUD, the timeline and the side panel
// (transfer function and quality) — and the report of their layout for tests.
//
// Panel layout (draw_ui): the timeline along the bottom edge, the HUD in the top-left corner above
// it, and the side panel at the top right when it fits beside the HUD, otherwise below the HUD,
// never taller than the space above the timeline. Below 560 × 400 pixels the HUD and the timeline
// switch to a compact form, so nothing overlaps down to about 320 × 240.
#include "player_impl.hpp"

#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_vulkan.h>
#include <imgui.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace volreel::app::detail {
namespace {

/// The rectangle of the ImGui window being drawn (between Begin and End).
ScreenRect current_window_rect() {
  const ImVec2 pos = ImGui::GetWindowPos(), size = ImGui::GetWindowSize();
  return {pos.x, pos.y, size.x, size.y, true};
}

/// Width of a button with this label, pixels.
float button_width(const char* label) {
  return ImGui::CalcTextSize(label, nullptr, true).x + 2 * ImGui::GetStyle().FramePadding.x;
}

/// Width of a checkbox with this label, pixels.
float checkbox_width(const char* label) {
  return ImGui::GetFrameHeight() + ImGui::GetStyle().ItemInnerSpacing.x +
         ImGui::CalcTextSize(label, nullptr, true).x;
}

/// Continues the current row when an item `width` pixels wide still fits in the window, else
/// starts a new row: a flow layout, so a narrow window wraps its controls instead of clipping.
void same_line_if_fits(float width) {
  const float end = ImGui::GetItemRectMax().x + ImGui::GetStyle().ItemSpacing.x + width;
  if (end <= ImGui::GetWindowPos().x + ImGui::GetWindowContentRegionMax().x) ImGui::SameLine();
}

}  // namespace

void Player::report_layout() const {
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  std::printf("layout %.0fx%.0f:", double{size.x}, double{size.y});
  const auto print = [](const char* name, const ScreenRect& r, const char* note) {
    if (r.shown)
      std::printf(" %s %.0f %.0f %.0f %.0f%s;", name, double{r.x}, double{r.y}, double{r.width},
                  double{r.height}, note);
    else
      std::printf(" %s hidden;", name);
  };
  print("hud", hud_rect_, "");
  print("timeline", timeline_rect_, "");
  print("panel", panel_rect_, panel_collapsed_ ? " collapsed" : "");
  std::printf("\n");
  std::fflush(stdout);
}

void Player::draw_hud() {
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  const ImGuiStyle& style = ImGui::GetStyle();
  const ImGuiWindowFlags flags = ImGuiWindowFlags_NoDecoration | ImGuiWindowFlags_AlwaysAutoResize |
                                 ImGuiWindowFlags_NoSavedSettings |
                                 ImGuiWindowFlags_NoFocusOnAppearing | ImGuiWindowFlags_NoNav;
  // Top left, above the timeline; lines longer than the window is wide wrap.
  const float bottom = timeline_rect_.shown ? timeline_rect_.y - 8 : size.y - 10;
  const ImVec2 max_size(std::max(size.x - 20, 1.0f), std::max(bottom - 10, 1.0f));
  ImGui::SetNextWindowPos(ImVec2(10, 10), ImGuiCond_Always);
  ImGui::SetNextWindowSizeConstraints(ImVec2(0, 0), max_size);
  ImGui::SetNextWindowBgAlpha(0.55f);
  const bool open = ImGui::Begin("HUD", nullptr, flags);
  hud_rect_ = current_window_rect();
  if (open) {
    ImGui::PushTextWrapPos(std::min(max_size.x - style.WindowPadding.x,
                                    style.WindowPadding.x + ImGui::GetFontSize() * 36.0f));
    const double t = playhead_.position();
    const auto& ts = container_.manifest().timestamps;
    // Between keyframes k and k + 1 the picture interpolates both: say so, with the simulation
    // time interpolated from the manifest's timestamps.
    const auto k = static_cast<std::size_t>(std::floor(t));
    const double f = t - static_cast<double>(k);
    ImGui::TextUnformatted(options_.container.filename().string().c_str());
    if (compact_ui_) {
      // A small window: four short lines (position and transport, rate, streaming state).
      ImGui::Text("keyframe %.2f / %.0f  %s %s %.2gx", t, playhead_.last(),
                  playhead_.playing() ? "playing" : "paused", playhead_.reversed() ? "back" : "fwd",
                  playhead_.speed());
      ImGui::Text("%.1f fps  %.1f ms  %.2f MB/s  %ux%u", fps_.value, 1e3 * t_frame_.value,
                  mb_per_s_, render_extent_.width, render_extent_.height);
      ImGui::Text(
          "atlas %.0f%%  at target %.0f%%  holes %u",
          stats_.atlas_capacity ? 100.0 * stats_.atlas_occupied / stats_.atlas_capacity : 0.0,
          100.0 * stats_.fraction_at_target, stats_.holes);
    } else {
      if (f < 1e-6)
        ImGui::Text("keyframe %.2f / %.0f   frame %zu", t, playhead_.last(), k);
      else
        ImGui::Text("keyframe %.2f / %.0f   frames %zu-%zu (f = %.2f)", t, playhead_.last(), k,
                    k + 1, f);
      if (k < ts.size()) {
        const double time = k + 1 < ts.size() ? ts[k] + f * (ts[k + 1] - ts[k]) : ts[k];
        ImGui::SameLine();
        ImGui::Text("  t = %.4g", time);
      }
      ImGui::Text("%s %s %.2gx%s", playhead_.playing() ? "playing" : "paused",
                  playhead_.reversed() ? "backward" : "forward", playhead_.speed(),
                  playhead_.options().loop ? "  loop" : "");
      ImGui::Separator();
      ImGui::Text("%.1f fps   frame %.1f ms", fps_.value, 1e3 * t_frame_.value);
      const auto ms = [](bool measured, const Smoothed& v) {
        char text[32] = "-";
        if (measured) std::snprintf(text, sizeof text, "%.2f", v.value);
        return std::string(text);
      };
      ImGui::Text("schedule %.2f  upload %.2f  decode %s  render %s  wait %.2f ms",
                  t_schedule_.value, t_upload_.value, ms(decode_measured_, t_decode_).c_str(),
                  ms(render_measured_, t_render_).c_str(), 1e3 * t_wait_.value);
      ImGui::Text("image %ux%u (%.0f%% of the side, %s)", render_extent_.width,
                  render_extent_.height, 100.0 * options_.render_scale * frame_scale_,
                  options_.frame_ms <= 0 ? "fixed"
                  : busy_                ? "busy: reduced to hold the frame time"
                                         : "still: full");
      ImGui::Checkbox("exact timings (no overlap)", &exact_timings_);
      ImGui::Text(
          "atlas %u / %u slots (%.0f%%)", stats_.atlas_occupied, stats_.atlas_capacity,
          stats_.atlas_capacity ? 100.0 * stats_.atlas_occupied / stats_.atlas_capacity : 0.0);
      ImGui::Text("requests in flight %zu   %.2f MB/s   uploads %zu", stats_.requests_in_flight,
                  mb_per_s_, stats_.uploads);
      ImGui::Text("at target LOD %.0f%% of %u nodes   holes %u", 100.0 * stats_.fraction_at_target,
                  stats_.target_nodes, stats_.holes);
      ImGui::TextDisabled("%s", renderer_->name().c_str());
    }
    const auto& errors = renderer_->scheduler().errors();
    if (!errors.empty()) {
      ImGui::Separator();
      ImGui::TextColored(ImVec4(1.0f, 0.45f, 0.35f, 1.0f),
                         "%zu problem(s), newest:", renderer_->scheduler().error_count());
      const std::size_t shown = std::min<std::size_t>(errors.size(), compact_ui_ ? 1 : 4);
      ImGui::PushStyleColor(ImGuiCol_Text, ImVec4(1.0f, 0.6f, 0.5f, 1.0f));
      for (std::size_t i = errors.size() - shown; i < errors.size(); ++i)
        ImGui::TextUnformatted(errors[i].c_str());
      ImGui::PopStyleColor();
    }
    ImGui::PopTextWrapPos();
  }
  ImGui::End();
}

void Player::draw_timeline() {
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  const ImGuiStyle& style = ImGui::GetStyle();
  // Along the bottom edge, as wide as the window; its height follows its rows (0: auto-fit).
  ImGui::SetNextWindowPos(ImVec2(10, size.y - 10), ImGuiCond_Always, ImVec2(0, 1));
  ImGui::SetNextWindowSize(ImVec2(std::max(size.x - 20, 1.0f), 0), ImGuiCond_Always);
  ImGui::SetNextWindowBgAlpha(0.6f);
  const ImGuiWindowFlags flags =
      ImGuiWindowFlags_NoDecoration | ImGuiWindowFlags_NoSavedSettings | ImGuiWindowFlags_NoMove;
  const bool open = ImGui::Begin("Timeline", nullptr, flags);
  timeline_rect_ = current_window_rect();
  if (open) {
    // Transport buttons, reverse, speed and reset view on one row while they fit (a narrow window
    // wraps them onto more rows), then the slider across the whole width.
    if (ImGui::Button("|<")) press(GLFW_KEY_HOME);
    same_line_if_fits(button_width("<"));
    if (ImGui::Button("<")) press(GLFW_KEY_LEFT);
    same_line_if_fits(button_width("pause"));
    if (ImGui::Button(playhead_.playing() ? "pause" : "play ")) press(GLFW_KEY_SPACE);
    same_line_if_fits(button_width(">"));
    if (ImGui::Button(">")) press(GLFW_KEY_RIGHT);
    same_line_if_fits(button_width(">|"));
    if (ImGui::Button(">|")) press(GLFW_KEY_END);
    same_line_if_fits(checkbox_width("reverse"));
    bool reversed = playhead_.reversed();
    if (ImGui::Checkbox("reverse", &reversed)) playhead_.set_reversed(reversed);
    const float speed_width = compact_ui_ ? 70.0f : 110.0f;
    same_line_if_fits(speed_width + style.ItemInnerSpacing.x + ImGui::CalcTextSize("speed").x);
    ImGui::SetNextItemWidth(speed_width);
    static constexpr std::array<double, 6> speeds{0.25, 0.5, 1, 2, 4, 8};
    char label[32];
    std::snprintf(label, sizeof label, "%.2gx", playhead_.speed());
    if (ImGui::BeginCombo("speed", label)) {
      for (double s : speeds) {
        std::snprintf(label, sizeof label, "%.2gx", s);
        if (ImGui::Selectable(label, s == playhead_.speed())) playhead_.set_speed(s);
      }
      ImGui::EndCombo();
    }
    same_line_if_fits(button_width("reset view"));
    if (ImGui::Button("reset view")) press(GLFW_KEY_C);
    ImGui::SetNextItemWidth(-1);
    float t = static_cast<float>(playhead_.position());
    if (ImGui::SliderFloat("##time", &t, 0.0f, static_cast<float>(playhead_.last()),
                           "keyframe %.2f"))
      playhead_.seek(t);
  }
  ImGui::End();
}

void Player::draw_panel() {
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  const float width = std::min(330.0f, std::max(size.x - 20, 1.0f));
  // Top right when it fits beside the HUD, else right below the HUD; never over the timeline
  // (a panel taller than the space left scrolls).
  const bool beside = !hud_rect_.shown || hud_rect_.right() + 10 + width <= size.x - 10;
  const float top = beside ? 10.0f : hud_rect_.bottom() + 8;
  const float bottom = timeline_rect_.shown ? timeline_rect_.y - 8 : size.y - 10;
  const float max_height = std::max(bottom - top, ImGui::GetFrameHeight());
  ImGui::SetNextWindowPos(ImVec2(size.x - 10, top), ImGuiCond_Always, ImVec2(1, 0));
  ImGui::SetNextWindowSizeConstraints(ImVec2(width, 0), ImVec2(width, max_height));
  ImGui::SetNextWindowCollapsed(size.x < 1000, ImGuiCond_FirstUseEver);
  const bool open =
      ImGui::Begin("Transfer function & quality", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
  panel_rect_ = current_window_rect();
  panel_collapsed_ = ImGui::IsWindowCollapsed();
  if (open) {
    const auto& names = cpu_render::TransferFunction::preset_names();
    const char* current =
        preset_ >= 0 ? names[static_cast<std::size_t>(preset_)].c_str() : "(custom)";
    if (ImGui::BeginCombo("preset", current)) {
      for (const auto& n : names)
        if (ImGui::Selectable(n.c_str(), n == current)) apply_preset(n);
      ImGui::EndCombo();
    }
    if (ImGui::SliderFloat("preset opacity", &preset_opacity_, 0.0f, 4.0f) && preset_ >= 0)
      apply_preset(names[static_cast<std::size_t>(preset_)]);
    bool changed = false;
    float range[2] = {range_lo_, range_hi_};
    if (ImGui::DragFloat2("range", range, (range_hi_ - range_lo_) * 0.005f) &&
        range[1] > range[0]) {
      range_lo_ = range[0];
      range_hi_ = range[1];
      changed = true;
    }
    // The table as a strip of opacity values, to see what the points make.
    std::array<float, 128> alpha{};
    for (std::size_t i = 0; i < alpha.size(); ++i)
      alpha[i] = transfer_.lookup(range_lo_ + (range_hi_ - range_lo_) * float(i) / 127.0f)[3];
    ImGui::PlotLines("opacity", alpha.data(), static_cast<int>(alpha.size()), 0, nullptr, 0.0f,
                     FLT_MAX, ImVec2(0, 50));
    ImGui::Text("control points (value, opacity, colour)");
    int remove = -1;
    for (std::size_t i = 0; i < points_.size(); ++i) {
      auto& p = points_[i];
      ImGui::PushID(static_cast<int>(i));
      ImGui::SetNextItemWidth(90);
      changed |= ImGui::DragFloat("##v", &p.value, (range_hi_ - range_lo_) * 0.002f, 0, 0, "%.4g");
      ImGui::SameLine();
      ImGui::SetNextItemWidth(90);
      changed |= ImGui::SliderFloat("##a", &p.a, 0.0f, 1.0f, "a %.3f");
      ImGui::SameLine();
      float rgb[3] = {p.r, p.g, p.b};
      if (ImGui::ColorEdit3("##c", rgb, ImGuiColorEditFlags_NoInputs)) {
        p.r = rgb[0];
        p.g = rgb[1];
        p.b = rgb[2];
        changed = true;
      }
      ImGui::SameLine();
      if (ImGui::SmallButton("x") && points_.size() > 1) remove = static_cast<int>(i);
      ImGui::PopID();
    }
    if (remove >= 0) {
      points_.erase(points_.begin() + remove);
      changed = true;
    }
    if (ImGui::Button("add point")) {
      cpu_render::ControlPoint p;
      p.value = 0.5f * (range_lo_ + range_hi_);
      const auto rgba = transfer_.lookup(p.value);
      p.r = rgba[0];
      p.g = rgba[1];
      p.b = rgba[2];
      p.a = rgba[3];
      points_.push_back(p);
      changed = true;
    }
    if (changed) {
      preset_ = -1;
      rebuild_transfer();
    }
    ImGui::Separator();
    ImGui::SliderFloat("SSE target (px)", &sse_target_, 0.25f, 16.0f, "%.2f",
                       ImGuiSliderFlags_Logarithmic);
    ImGui::TextDisabled("lower: finer detail, more bricks");
  }
  ImGui::End();
}

void Player::draw_ui() {
  hud_rect_ = timeline_rect_ = panel_rect_ = ScreenRect{};
  if (!show_ui_) return;
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  compact_ui_ = size.x < 560 || size.y < 400;
  // The timeline first: the HUD and the panel are placed in the space above it.
  draw_timeline();
  draw_hud();
  draw_panel();
}

}  // namespace volreel::app::detail
