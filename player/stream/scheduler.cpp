// scheduler.cpp: one frame of the patent's streaming (Cesium patent [0035]–[0049], [0060]–[0075]).
#include "volreel/stream/scheduler.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

namespace volreel::stream {

namespace {

/// The settings with the container's brick reader, unless they name one.
SchedulerSettings reading_from(const format::Container& container, SchedulerSettings settings) {
  if (!settings.loader.reader) settings.loader.reader = container.source().brick_reader();
  return settings;
}

}  // namespace

StreamScheduler::StreamScheduler(const format::Container& container, SchedulerSettings settings)
    : StreamScheduler(container, std::move(settings), IndexOptions{}) {}

StreamScheduler::StreamScheduler(const format::Container& container, SchedulerSettings settings,
                                 const IndexOptions& index_options)
    : StreamScheduler(SpatialIndex{}, reading_from(container, std::move(settings))) {
  std::vector<std::string> errors;
  index_ = build_spatial_index(container, &errors, index_options);
  random_table_ = random_selection_table(index_.frame_count());
  for (std::string& e : errors) add_error(std::move(e));
}

StreamScheduler::StreamScheduler(SpatialIndex index, SchedulerSettings settings)
    : index_(std::move(index)),
      settings_(settings),
      atlas_(std::max<std::uint32_t>(1, settings.atlas_slots)),
      loader_(settings.loader),
      heap_(std::max<std::uint32_t>(1, settings.atlas_slots)),
      random_table_(random_selection_table(index_.frame_count())) {}

void StreamScheduler::add_error(std::string message) {
  ++error_count_;
  frame_errors_.push_back(message);
  errors_.push_back(std::move(message));
  while (errors_.size() > std::max<std::size_t>(1, settings_.max_messages)) errors_.pop_front();
}

void StreamScheduler::report_error(std::string message) {
  add_error(std::move(message));
}

void StreamScheduler::end_request(KeyframeId id) {
  const auto it = in_flight_.find(id);
  if (it == in_flight_.end()) return;
  in_flight_bytes_ -= it->second.bytes;
  if (it->second.speculative) speculative_bytes_ -= it->second.bytes;
  in_flight_.erase(it);
}

void StreamScheduler::select(const player::OrbitCamera& camera, double playhead) {
  heap_.clear();
  selection_.clear();
  view_.run(index_, camera, settings_.priority.sse_target, settings_.priority.restricted);
  // Ray-guided feedback: visited nodes no ray reached in the last frame drawn (not the root).
  for (const std::uint32_t n : hidden_list_) hidden_[n] = 0;
  hidden_list_.clear();
  hidden_.resize(index_.node_count(), 0);
  if (settings_.ray_feedback && feedback_current())
    for (const ViewTraversal::Visit& v : view_.visits())
      if (v.node != 0 && ray_priority(v.node) == priority_hidden) {
        hidden_[v.node] = 1;
        hidden_list_.push_back(v.node);
      }
  const PrioritySettings& ps = settings_.priority;
  const std::size_t frames = index_.frame_count();
  const bool patent = ps.policy == PriorityPolicy::patent;
  const bool due_window = patent && ps.due_window;
  const double velocity = motion_.velocity();
  const auto higher_first = [](const HeapEntry& a, const HeapEntry& b) { return HeapLess{}(b, a); };

  // Keyframe nodes in the due window. Their priorities lie above every other's
  // (due_priority > sse_weight + 1 ≥ combined_priority when sse_weight ≥ 0): when there are at
  // least as many as the atlas has slots, the selection is the best of them and nothing else is
  // looked at. Otherwise they all enter the heap.
  if (due_window) {
    for (const ViewTraversal::Visit& v : view_.visits()) {
      if (hidden_[v.node]) continue;
      due_times(index_.times(v.node), playhead, velocity, ps.lookahead_s, due_);
      const std::uint32_t level = index_.node(v.node).key.level;
      for (const DueTime& d : due_)
        selection_.push_back({due_priority(d.seconds, ps), level, keyframe_id(v.node, d.t), true});
    }
    const std::size_t slots = heap_.capacity();
    if (selection_.size() >= slots && ps.sse_weight >= 0) {
      const auto kept = selection_.begin() + static_cast<std::ptrdiff_t>(slots);
      if (selection_.size() > slots)
        std::nth_element(selection_.begin(), kept, selection_.end(), higher_first);
      selection_.erase(kept, selection_.end());
      std::sort(selection_.begin(), selection_.end(), higher_first);
      return;
    }
    for (const HeapEntry& e : selection_) heap_.push(e);
    selection_.clear();
  }

  // The temporal priority depends on the keyframe only: once per held keyframe per frame.
  temporal_.resize(frames);
  for (std::size_t t = index_.held_begin(); t < index_.held_end(); ++t)
    temporal_[t] =
        temporal_priority(static_cast<double>(t), playhead, frames, ps.temporal_exponent);
  // SseScope::level: one SSE per level, the largest of its visited nodes.
  const bool level_sse = patent && ps.sse_scope == SseScope::level;
  if (level_sse) {
    level_sse_.assign(index_.level_count(), 0.0);
    for (const ViewTraversal::Visit& v : view_.visits()) {
      double& sse = level_sse_[index_.node(v.node).key.level];
      sse = std::max(sse, v.sse);
    }
  }
  // A keyframe node's priority outside the due window is its node's SSE part plus a part of its
  // time step alone ([0045]), so every node takes the held time steps in one order (that part
  // descending) and stops at the first whose priority cannot enter the full heap.
  by_time_.clear();
  for (std::uint32_t t = index_.held_begin(); t < index_.held_end(); ++t)
    by_time_.emplace_back(combined_priority(0.0, temporal_[t], random_table_[t], ps), t);
  std::sort(by_time_.begin(), by_time_.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second < b.second;
  });
  for (const ViewTraversal::Visit& v : view_.visits()) {
    // A hidden node's keyframe nodes come after every other's and are never requested: those
    // resident stay while the atlas has room for them.
    const bool hidden = hidden_[v.node] != 0;
    const double demotion = hidden ? hidden_demotion : 0.0;
    const SpatialNode& n = index_.node(v.node);
    const double sse_p = sse_priority(level_sse ? level_sse_[n.key.level] : v.sse);
    // A node whose best possible priority cannot enter a full heap is skipped whole.
    const double best = (patent ? ps.sse_weight * sse_p + 1.0 : 1.0) - demotion;
    if (heap_.full() && best < heap_.min().priority) continue;
    const HeldTimes times = index_.times(v.node);
    if (times.empty()) continue;
    bool due_known = false;  // due_ filled for this node (on its first step in)
    for (const auto& [part, t] : by_time_) {
      const double priority =
          combined_priority(sse_p, temporal_[t], random_table_[t], ps) - demotion;
      if (heap_.full() && priority < heap_.min().priority) break;
      if (!times.contains(t)) continue;
      if (!due_known) {
        if (due_window && !hidden)
          due_times(times, playhead, velocity, ps.lookahead_s, due_);
        else
          due_.clear();
        due_known = true;
      }
      // The due ones entered above.
      if (std::any_of(due_.begin(), due_.end(), [t](const DueTime& d) { return d.t == t; }))
        continue;
      heap_.push({priority, n.key.level, keyframe_id(v.node, t), false, hidden});
    }
  }
  while (!heap_.empty()) selection_.push_back(heap_.pop_max());
}

bool StreamScheduler::selected(KeyframeId id) const {
  const auto it = std::lower_bound(selected_.begin(), selected_.end(), id,
                                   [](const auto& s, KeyframeId v) { return s.first < v; });
  return it != selected_.end() && it->first == id;
}

FrameUpdate StreamScheduler::update(const player::OrbitCamera& camera, double playhead,
                                    std::uint64_t gpu_frame_number) {
  FrameUpdate out;
  const double last = index_.frame_count() > 0 ? static_cast<double>(index_.frame_count() - 1) : 0;
  playhead = std::clamp(playhead, 0.0, last);

  // 1. Arrivals.
  for (BrickArrival& a : loader_.poll()) {
    end_request(a.request.keyframe);
    if (!a.ok()) {
      add_error(a.error + " (will retry)");
      continue;
    }
    const KeyframeId id = a.request.keyframe;
    waiting_.insert_or_assign(id, std::move(a));
  }

  // 2. The index's time window follows the playhead; priorities into the heap; its contents are
  // the selected set.
  motion_.observe(loader_.now_seconds(), playhead);
  {
    std::vector<std::string> index_errors;
    index_.follow(playhead, motion_.velocity(), &index_errors);
    for (std::string& e : index_errors) add_error(std::move(e));
  }
  select(camera, playhead);
  selected_.clear();
  for (std::size_t i = 0; i < selection_.size(); ++i)
    selected_.emplace_back(selection_[i].keyframe, static_cast<std::uint32_t>(i));
  std::sort(selected_.begin(), selected_.end());

  // 3. Atlas lists: release what is no longer selected, re-occupy what is selected again.
  for (const std::uint32_t slot : atlas_.occupied_slots()) {
    const auto key = atlas_.key(slot);
    if (!key || !selected(index_.find_keyframe(*key))) atlas_.release_slot(slot);
  }
  // Every occupied slot now holds a selected keyframe node: where each one is, by its position
  // in the selection (nothing else changes them this frame but the uploads below).
  slot_of_.assign(selection_.size(), no_slot);
  for (const auto& [id, i] : selected_)
    if (const auto slot = atlas_.reoccupy(index_.key(id))) slot_of_[i] = *slot;

  // 4. Arrivals into slots, within the upload budget (highest priority first).
  {
    const std::vector<HeapEntry>& entries = selection_;
    std::uint64_t budget_used = 0;
    for (std::size_t i = 0; i < entries.size(); ++i) {
      const HeapEntry& e = entries[i];
      const auto it = waiting_.find(e.keyframe);
      if (it == waiting_.end()) continue;
      const KeyframeKey key = index_.key(e.keyframe);
      const std::uint64_t bytes = it->second.bytes.size();
      if (!out.uploads.empty() && budget_used + bytes > settings_.upload_budget_bytes) break;
      if (slot_of_[i] != no_slot) {  // already resident (re-requested meanwhile)
        waiting_.erase(it);
        continue;
      }
      const auto slot = atlas_.acquire(key);
      if (!slot) break;  // no slot free of in-flight GPU frames: next frame
      slot_of_[i] = *slot;
      BrickUpload u;
      u.slot = *slot;
      u.key = key;
      u.payload = std::move(it->second.bytes);
      u.constant = u.payload.size() == 4;
      u.file = std::move(it->second.request.file);
      u.offset = it->second.request.offset;
      budget_used += bytes;
      out.uploads.push_back(std::move(u));
      waiting_.erase(it);
    }
    // Arrivals whose keyframe node is no longer selected are discarded ([0037]).
    for (auto it = waiting_.begin(); it != waiting_.end();) {
      if (!selected(it->first)) {
        it = waiting_.erase(it);
        ++out.stats.arrivals_discarded;
      } else {
        ++it;
      }
    }
    out.stats.bytes_uploaded = budget_used;

    // 5. Requests in priority order ([0063]); queued ones no longer selected are cancelled.
    loader_.cancel_queued([&](const BrickRequest& r) {
      const bool keep = selected(r.keyframe);
      if (!keep) end_request(r.keyframe);
      return keep;
    });
    // Speculative requests (outside the due window) only while the link's backlog is short.
    const double bandwidth = settings_.loader.bandwidth_bytes_per_s;
    const bool bounded = settings_.priority.policy == PriorityPolicy::patent &&
                         settings_.priority.due_window && bandwidth > 0 &&
                         settings_.speculative_link_s > 0;
    const double speculative_limit = bounded ? bandwidth * settings_.speculative_link_s : 0;
    for (std::size_t i = 0; i < entries.size(); ++i) {
      const HeapEntry& e = entries[i];
      if (slot_of_[i] != no_slot || waiting_.count(e.keyframe) || e.hidden) continue;
      const KeyframeNode& k = index_.keyframe(e.keyframe);
      // Entries come highest priority first and due ones before all others: once a speculative
      // one does not fit the bound, none after it does (one is allowed on an idle link).
      if (bounded && !e.due && in_flight_bytes_ > 0 &&
          static_cast<double>(in_flight_bytes_ + k.bytes) > speculative_limit)
        break;
      const RequestStatus s = loader_.request(brick_request(index_, e.keyframe));
      if (s == RequestStatus::accepted) {
        ++out.stats.requests_sent;
        const bool speculative = bounded && !e.due;
        if (in_flight_.emplace(e.keyframe, InFlight{k.bytes, speculative}).second) {
          in_flight_bytes_ += k.bytes;
          if (speculative) speculative_bytes_ += k.bytes;
        }
      }
      if (s == RequestStatus::at_capacity) break;
    }
    out.stats.selected = static_cast<std::uint32_t>(entries.size());
  }

  // 6. Pre-render selection and the SVO, from occupied slots only.
  {
    std::vector<ResidentKeyframe> resident;
    resident.reserve(selection_.size());
    for (std::size_t i = 0; i < selection_.size(); ++i)
      if (slot_of_[i] != no_slot) resident.push_back({selection_[i].keyframe, slot_of_[i]});
    // A fade-out on collapse draws the children of a node they drew in the last build (or that
    // was fading out then), and that the view now targets, from their own bricks while it lasts.
    // They are no longer selected, but their slots keep them until overwritten (over-writeable),
    // and the build marks the slots it draws from as used, so that no upload overwrites them while
    // a GPU frame samples them.
    // A node collapses where this view targets it and the last build drew it refined (or it was
    // fading out then). Only below such a node (the builder visits none of its children, so
    // nothing but the fade draws from these bricks), and only in frames that have one: the scan
    // of the over-writeable slots is skipped otherwise.
    const auto collapses = [&](std::uint32_t node) {
      return node < blend_.region_build.size() &&
             ((blend_.region_build[node] == blend_.build && blend_.region_refined[node]) ||
              blend_.out_build[node] == blend_.build);
    };
    const bool any_collapse =
        settings_.lod_blend.fade_out_s > 0 && blend_.build > 0 &&
        std::any_of(view_.visits().begin(), view_.visits().end(),
                    [&](const ViewTraversal::Visit& v) { return !v.refine && collapses(v.node); });
    if (any_collapse)
      for (const std::uint32_t slot : atlas_.overwriteable_slots()) {
        const auto key = atlas_.key(slot);
        const KeyframeId id = key ? index_.find_keyframe(*key) : no_keyframe;
        if (id == no_keyframe) continue;
        const std::uint32_t parent = index_.node(SpatialIndex::node_of(id)).parent;
        if (parent != no_node && view_.visited(parent) && !view_.visit(parent).refine &&
            collapses(parent))
          resident.push_back({id, slot});
      }
    resident_.assign(index_, resident);
    SvoStats svo_stats;
    blend_.settings = settings_.lod_blend;
    // The blending state also holds the restricted drawing's scratch (build_svo uses it alone
    // when nothing blends).
    built_at_ = loader_.now_seconds();
    SvoArrays svo = build_svo(index_, view_, resident_, playhead, settings_.selection, &svo_stats,
                              &stored_times_, hidden_, &blend_, *built_at_);
    out.stats.blended_leaves = svo_stats.blended_leaves;
    out.stats.restricted_nodes = svo_stats.restricted_nodes;
    for (const std::uint32_t slot : svo_stats.used_slots) atlas_.mark_used(slot, gpu_frame_number);
    if (settings_.ray_feedback) keep_svo_regions(svo, gpu_frame_number);
    out.stats.hidden_nodes = static_cast<std::uint32_t>(hidden_list_.size());
    out.stats.hidden_targets = svo_stats.hidden_targets;
    out.stats.forced_nodes = static_cast<std::uint32_t>(view_.forced_count());
    out.svo_nodes = std::move(svo.nodes);
    out.svo_leaves = std::move(svo.leaves);
    out.stats.target_nodes = svo_stats.target_nodes;
    out.stats.at_target_nodes = svo_stats.at_target_nodes;
    out.stats.index_ready = index_.holds_around(playhead);
    out.stats.index_failed = index_.failed_around(playhead);
    out.stats.fraction_at_target =
        !out.stats.index_ready || out.stats.index_failed ? 0.0
        : svo_stats.target_nodes > 0
            ? static_cast<double>(svo_stats.at_target_nodes) / svo_stats.target_nodes
            : 1.0;
    out.stats.holes = svo_stats.holes;
    out.stats.svo_nodes = svo_stats.node_records;
    out.stats.svo_leaves = svo_stats.leaf_records;
  }

  out.stats.uploads = out.uploads.size();
  out.stats.requests_in_flight = loader_.in_flight();
  out.stats.arrivals_waiting = waiting_.size();
  out.stats.bytes_loaded = loader_.bytes_read();
  out.stats.bricks_loaded = loader_.bricks_read();
  out.stats.loader_reads = loader_.reads();
  out.stats.atlas_occupied = atlas_.occupied_count();
  out.stats.atlas_capacity = atlas_.capacity();
  out.stats.errors = error_count_;
  out.new_errors = std::move(frame_errors_);
  frame_errors_.clear();
  return out;
}

SvoArrays StreamScheduler::previous_svo(double playhead) const {
  if (!built_at_) return {};
  const double last = index_.frame_count() > 0 ? static_cast<double>(index_.frame_count() - 1) : 0;
  // A copy of the blending state, at the last build's time: the regions this build draws are
  // those of the last one, so no fade starts and every weight is as it was drawn.
  LodBlendState blend = blend_;
  return build_svo(index_, view_, resident_, std::clamp(playhead, 0.0, last), settings_.selection,
                   nullptr, nullptr, hidden_, &blend, *built_at_);
}

// ---- Ray-guided feedback (Thiele, Matthes, Froehlich, §3) -------------------------------------

void StreamScheduler::keep_svo_regions(const SvoArrays& svo, std::uint64_t gpu_frame_number) {
  // A later update for the same GPU frame (a stream step before it is drawn) replaces the SVO.
  if (kept_svos_.empty() || kept_svos_.back().gpu_frame != gpu_frame_number) {
    const std::size_t keep = std::max<std::uint32_t>(settings_.feedback_frames, 1);
    if (kept_svos_.size() < keep) {
      kept_svos_.emplace_back();
    } else {  // reuse the oldest one's storage
      KeptSvo oldest = std::move(kept_svos_.front());
      kept_svos_.pop_front();
      kept_svos_.push_back(std::move(oldest));
    }
  }
  KeptSvo& k = kept_svos_.back();
  k.gpu_frame = gpu_frame_number;
  k.regions.clear();
  k.record_nodes = svo.node_ids;
  k.record_parents.clear();
  k.leaf_count = svo.leaves.size() / VR_SVO_LEAF_WORDS;
  for (std::uint32_t r = 0; r < svo.node_ids.size(); ++r) {
    const std::uint32_t* words = svo.nodes.data() + std::size_t{r} * VR_SVO_NODE_WORDS;
    k.record_parents.push_back(words[0]);
    const std::uint32_t id = svo.node_ids[r];
    if (id == no_node) continue;
    const SpatialNode& n = index_.node(id);
    // A record that is not refined in the view (the root drawn as a leaf) and a record without
    // children draw their own region in every octant.
    const bool own = !view_.visited(id) || !view_.visit(id).refine || !n.has_children;
    for (std::uint32_t i = 0; i < 8; ++i) {
      const std::uint32_t word = words[1 + i];
      const std::uint32_t child = own ? id : n.children[i];
      if (child == no_node) continue;  // outside the volume
      switch (vr_svo_child_kind(word)) {
        case VR_SVO_CHILD_LEAF:
          k.regions.push_back({r, child, VR_SVO_FEEDBACK_ENTRIES * vr_svo_child_index(word)});
          break;
        case VR_SVO_CHILD_UP:
          // Outside the view: no ray could have gone there.
          k.regions.push_back(
              {r, child,
               own || view_.visited(child) ? VR_SVO_FEEDBACK_ENTRIES * words[9] + i : no_entry});
          break;
        case VR_SVO_CHILD_EMPTY:
          k.regions.push_back({r, child, no_entry});  // a hole: nothing could be sampled
          break;
        default:
          break;  // a node record: its own regions
      }
    }
  }
}

void StreamScheduler::feedback(std::span<const std::uint32_t> leaves) {
  if (!settings_.ray_feedback) return;  // ignored
  if (kept_svos_.empty())
    throw std::invalid_argument("ray feedback: no SVO was built yet (call update() first)");
  feedback(leaves, kept_svos_.back().gpu_frame);
}

bool StreamScheduler::feedback(std::span<const std::uint32_t> leaves,
                               std::uint64_t gpu_frame_number) {
  const auto kept = std::find_if(kept_svos_.begin(), kept_svos_.end(),
                                 [&](const KeptSvo& k) { return k.gpu_frame == gpu_frame_number; });
  if (!settings_.ray_feedback) return false;  // ignored (no SVO regions are kept)
  if (kept == kept_svos_.end() || (feedback_stamp_ != 0 && gpu_frame_number < feedback_frame_) ||
      gpu_frame_number < forgotten_frame_)
    return false;
  const KeptSvo& svo = *kept;
  if (leaves.size() != VR_SVO_FEEDBACK_ENTRIES * svo.leaf_count)
    throw std::invalid_argument(
        "ray feedback for GPU frame " + std::to_string(gpu_frame_number) + ": expected " +
        std::to_string(VR_SVO_FEEDBACK_ENTRIES * svo.leaf_count) + " entries (" +
        std::to_string(VR_SVO_FEEDBACK_ENTRIES) + " per leaf record of its SVO), found " +
        std::to_string(leaves.size()));
  if (priority_stamps_.size() != index_.node_count()) {
    priority_stamps_.assign(index_.node_count(), 0);
    ray_priority_.assign(index_.node_count(), priority_hidden);
  }
  if (++priority_stamp_ == 0) {  // wrapped: no node may keep a stamp that looks current
    std::fill(priority_stamps_.begin(), priority_stamps_.end(), 0u);
    priority_stamp_ = 1;
  }
  feedback_stamp_ = priority_stamp_;
  feedback_frame_ = gpu_frame_number;
  const auto up = [](std::int32_t p) {  // one level up: +1, ±∞ stay
    return p == priority_hidden || p == priority_unknown ? p : p + 1;
  };
  const auto set = [&](std::uint32_t node, std::int32_t p) {
    if (priority_stamps_[node] != feedback_stamp_) {
      priority_stamps_[node] = feedback_stamp_;
      ray_priority_[node] = p;
    } else {
      ray_priority_[node] = std::max(ray_priority_[node], p);
    }
  };
  // A region's priority is its leaf's feedback: the largest LOD difference its rays sampled,
  // −∞ when none did.
  record_priority_.assign(svo.record_nodes.size(), priority_hidden);
  for (const SvoRegion& g : svo.regions) {
    const std::int32_t p =
        g.entry == no_entry ? priority_unknown
        : leaves[g.entry] == 0
            ? priority_hidden
            : static_cast<std::int32_t>(std::min<std::uint32_t>(leaves[g.entry] - 1, 64));
    std::int32_t& r = record_priority_[g.record];
    if (g.node == svo.record_nodes[g.record]) {
      r = std::max(r, p);  // the record's own region
    } else {
      set(g.node, p);
      r = std::max(r, up(p));
    }
  }
  // Algorithm 1, bottom to top: a node record's priority is the largest of its children's + 1
  // (records come parents first).
  for (std::size_t r = svo.record_nodes.size(); r-- > 0;) {
    const std::uint32_t parent = svo.record_parents[r];
    if (parent != VR_SVO_NO_PARENT && parent < record_priority_.size())
      record_priority_[parent] = std::max(record_priority_[parent], up(record_priority_[r]));
    if (svo.record_nodes[r] != no_node) set(svo.record_nodes[r], record_priority_[r]);
  }
  return true;
}

void StreamScheduler::forget_feedback() {
  feedback_stamp_ = 0;
  if (!kept_svos_.empty()) forgotten_frame_ = kept_svos_.back().gpu_frame;
}

bool StreamScheduler::feedback_current() const {
  return feedback_stamp_ != 0 && !kept_svos_.empty() &&
         feedback_frame_ >= kept_svos_.front().gpu_frame;
}

std::int32_t StreamScheduler::ray_priority(std::uint32_t node) const {
  if (!feedback_current()) return priority_unknown;
  // Top to bottom: a node below the last SVO's region or record has its priority − 1 a level.
  std::int32_t below = 0;
  for (std::uint32_t n = node; n != no_node && n < priority_stamps_.size();
       n = index_.node(n).parent, ++below)
    if (priority_stamps_[n] == feedback_stamp_) {
      const std::int32_t p = ray_priority_[n];
      return p == priority_hidden || p == priority_unknown ? p : p - below;
    }
  return priority_unknown;
}

}  // namespace volreel::stream
