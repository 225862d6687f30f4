// scheduler.hpp: the patent's streaming, once per rendered frame (Cesium patent [0029]–[0075];
// docs/design.md, "Streaming"). update() runs, in order:
//   1. take the loader's arrivals (errors go to the message list);
//   2. walk the view (frustum, SSE) and fill the fixed-capacity min-max heap with the keyframe
//      nodes of the visited nodes by priority (priorities.hpp; with the patent policy, the due
//      window's keyframe nodes — around the playhead and ahead of it in its direction of travel,
//      the velocity estimated from successive playheads on the loader's clock — come first);
//      the heap's contents are this frame's selected set;
//   3. atlas: occupied slots whose keyframe node is no longer selected become over-writeable;
//      selected keyframe nodes still in an over-writeable slot re-occupy it without a request;
//   4. arrivals: those no longer selected are discarded (atlas untouched); the rest take a slot
//      (the stalest over-writeable one whose last GPU frame retired) within the per-frame upload
//      budget, and become uploads; what does not fit waits for the next frame;
//   5. requests: the heap drained from highest to lowest priority; selected keyframe nodes not in
//      the atlas are requested, up to the loader's cap on requests in flight (and, outside the due
//      window, up to speculative_link_s of the link's bandwidth); queued requests no longer
//      selected are cancelled;
//   6. pre-render selection and the array-encoded SVO (selection.hpp, svo_builder.hpp) from the
//      occupied slots only, with level-of-detail blending (SchedulerSettings::lod_blend); the
//      slots it references are marked used by this GPU frame.
// Ray-guided feedback (Thiele, Matthes, Froehlich, §3): a renderer that records, per leaf record of
// the SVO, whether rays sampled it (cpu_render::render_svo's feedback) hands the table to
// feedback(); priorities are distributed from it over that SVO (their Algorithm 1), and at the next
// update a visited node that no ray reached (behind opaque material, outside the image) is
// hidden: its keyframe nodes are never requested, and those resident rank below every other's
// (they stay while the atlas has room).
// The caller decodes each upload's payload into its slot before rendering with the SVO, and reports
// completed GPU frames with retire(). Problems (a bad frame file at index time, a failed read)
// become messages in errors(); update() does not throw on bad data.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "volreel/format/container.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/stream/atlas_slots.hpp"
#include "volreel/stream/brick_loader.hpp"
#include "volreel/stream/min_max_heap.hpp"
#include "volreel/stream/playhead.hpp"
#include "volreel/stream/priorities.hpp"
#include "volreel/stream/selection.hpp"
#include "volreel/stream/spatial_index.hpp"
#include "volreel/stream/svo_builder.hpp"

namespace volreel::stream {

struct SchedulerSettings {
  std::uint32_t atlas_slots = 512;  ///< brick slots of the atlas = heap capacity ([0036])
  PrioritySettings priority;
  SelectionSettings selection;
  LoaderOptions loader;
  /// With the due window (patent policy): a request outside it ("speculative": the [0045] order)
  /// goes out only while all requests in flight hold less than this many seconds of the link's
  /// bandwidth. Speculative requests so take only the link time the due window leaves, and the
  /// keyframes the playhead needs next (after a seek, a start or a change of direction) never
  /// queue behind more than this much of them ([0037]: lower-priority requests throttled and tried
  /// again later). 0 or an unlimited link: no bound beyond the loader's cap on requests in flight.
  double speculative_link_s = 0.15;
  std::uint64_t upload_budget_bytes = 64ull << 20;  ///< payload bytes uploaded per frame at most
                                                    ///< (at least one upload per frame)
  std::size_t max_messages = 64;                    ///< messages kept for the UI (newest)
  /// Use the renderer's feedback (feedback()) to leave hidden nodes out of the selected set.
  bool ray_feedback = true;
  /// Feedback guides the selection while the frame it was drawn for is one of the last this many
  /// GPU frames (update()'s gpu_frame_number): a GPU's table arrives when its frame completes,
  /// frames in flight later. At least 1.
  std::uint32_t feedback_frames = 4;
  /// Level-of-detail blending in the SVO (svo_builder.hpp; the fade on the loader's clock).
  LodBlendSettings lod_blend;
};

/// One brick for the caller to decode into an atlas slot before rendering.
struct BrickUpload {
  std::uint32_t slot = 0;
  KeyframeKey key;
  std::vector<std::byte> payload;  ///< the brick's codec payload (format/SPEC.md "Brick payload")
  bool constant = false;           ///< a 4-byte payload: one float32 for every voxel
  std::filesystem::path file;      ///< frame file and payload offset, for error messages
  std::uint64_t offset = 0;
};

struct StreamStats {
  std::uint32_t target_nodes = 0;     ///< visible nodes at their target LOD (SvoStats)
  std::uint32_t at_target_nodes = 0;  ///< of those, drawn with both keyframes at full detail
  /// Visited nodes hidden by the ray feedback (none of their keyframe nodes selected), and of
  /// the target nodes those hidden (not in target_nodes).
  std::uint32_t hidden_nodes = 0, hidden_targets = 0;
  /// Visited nodes refined for the restricted working set alone (PrioritySettings::restricted).
  std::uint32_t forced_nodes = 0;
  /// Nodes drawn coarser for the restricted drawing (SelectionSettings::restricted).
  std::uint32_t restricted_nodes = 0;
  /// at_target_nodes / target_nodes (1 when none; 0 while the index does not hold the frames
  /// around the playhead, or one of them failed to read)
  double fraction_at_target = 0;
  bool index_ready = true;        ///< the index holds the frames around the playhead
  bool index_failed = false;      ///< a frame around the playhead failed to read (SpatialIndex)
  std::uint32_t holes = 0;        ///< target nodes with nothing to draw yet
  std::uint32_t selected = 0;     ///< keyframe nodes in the heap this frame
  std::size_t requests_sent = 0;  ///< this frame
  std::size_t requests_in_flight = 0;
  std::size_t arrivals_discarded = 0;  ///< this frame: no longer selected
  std::size_t arrivals_waiting = 0;    ///< arrived, not yet uploaded (budget or no free slot)
  std::size_t uploads = 0;             ///< this frame
  std::uint64_t bytes_uploaded = 0;    ///< this frame
  std::uint64_t bytes_loaded = 0;      ///< since construction, read by the loader
  std::uint64_t bricks_loaded = 0;     ///< since construction, read by the loader
  std::uint64_t loader_reads = 0;      ///< since construction (a coalesced read counts once)
  std::uint32_t atlas_occupied = 0, atlas_capacity = 0;
  std::uint32_t svo_nodes = 0, svo_leaves = 0;
  std::uint32_t blended_leaves = 0;  ///< leaf records that blend in their parent's drawing
  std::size_t errors = 0;            ///< since construction

  /// Nothing more is on its way for this view: the frame indexes around the playhead are read (or
  /// failed), no request is in flight, no arrival waits and nothing was uploaded this frame. Two
  /// such frames in a row: the scheduler had its chance to request more and did not.
  bool quiet() const {
    return (index_ready || index_failed) && requests_in_flight == 0 && arrivals_waiting == 0 &&
           uploads == 0;
  }
};

struct FrameUpdate {
  std::vector<BrickUpload> uploads;
  std::vector<std::uint32_t> svo_nodes;   ///< svo_layout.h node records
  std::vector<std::uint32_t> svo_leaves;  ///< svo_layout.h leaf records
  StreamStats stats;
  std::vector<std::string> new_errors;  ///< messages added since the previous update
};

class StreamScheduler {
 public:
  /// Indexes the container (bad frames become messages, not exceptions).
  StreamScheduler(const format::Container& container, SchedulerSettings settings);
  /// With the index's options (the memory it may hold: a time window beyond it).
  StreamScheduler(const format::Container& container, SchedulerSettings settings,
                  const IndexOptions& index_options);
  StreamScheduler(SpatialIndex index, SchedulerSettings settings);

  /// One rendered frame: camera, playhead (keyframe units) and the GPU frame number that will
  /// render the returned SVO (increasing).
  FrameUpdate update(const player::OrbitCamera& camera, double playhead,
                     std::uint64_t gpu_frame_number);
  /// Every GPU frame ≤ frame_number has completed (its fence signalled).
  void retire(std::uint64_t frame_number) { atlas_.retire(frame_number); }
  /// A problem found by the caller (a payload that failed to decode, …) for the message list.
  void report_error(std::string message);
  /// Ray-guided feedback for the SVO of the last update(): the feedback table of svo_layout.h
  /// (per region a leaf draws, 0 where no ray sampled it, else 1 + the largest LOD difference
  /// sampled; cpu_render::render_svo and the Vulkan ray caster write it).
  /// Priorities are distributed over that SVO (Algorithm 1: a region's is its entry − 1,
  /// or −∞ when no ray sampled it; a node record's the largest of its children's + 1; a node
  /// below a region the region's − 1 a level). At the next updates a visited node whose priority
  /// is −∞ is hidden, except the root: its keyframe nodes are not requested and rank below every
  /// other's (kept while resident and the atlas has room). Regions with nothing drawn (holes) or
  /// outside the view are unknown and never hide anything. The newest feedback counts, while its
  /// frame is one of the last SchedulerSettings::feedback_frames. Throws std::invalid_argument
  /// when no SVO was built yet or the table's size is not VR_SVO_FEEDBACK_ENTRIES per leaf record
  /// of the SVO.
  void feedback(std::span<const std::uint32_t> leaves);
  /// The same for the SVO of the last update() told `gpu_frame_number` (a frame that completed
  /// late). Returns false, and changes nothing, when that frame is no longer one of the last
  /// feedback_frames or is older than the feedback already given.
  bool feedback(std::span<const std::uint32_t> leaves, std::uint64_t gpu_frame_number);
  /// Drops the feedback given: until the next, nothing is hidden (for updates that draw nothing,
  /// such as a wait for a complete view, where no ray tells what the view reaches).
  /// Tables of frames before the last update's are refused after it.
  void forget_feedback();
  /// The SVO of the last update's view and resident keyframe nodes, blended as that update drew
  /// them, at playhead p: what the last frame's working set draws at a later time step (volreel
  /// bench stream compares it, drawn from the atlas before the next frame's uploads, with the next
  /// frame: the image change due to the working set alone). Changes nothing; empty arrays before
  /// the first update.
  SvoArrays previous_svo(double playhead) const;

  /// Whether the last update hid the node (feedback: no ray reached it).
  bool hidden(std::uint32_t node) const { return node < hidden_.size() && hidden_[node] != 0; }

  const SpatialIndex& index() const { return index_; }
  const AtlasSlots& atlas() const { return atlas_; }
  const BrickLoader& loader() const { return loader_; }
  const SchedulerSettings& settings() const { return settings_; }
  PrioritySettings& priority_settings() { return settings_.priority; }
  /// The playhead's velocity used by the due window, keyframes per second (negative: backwards).
  double playhead_velocity() const { return motion_.velocity(); }
  /// Bytes of speculative requests in flight (outside the due window when requested).
  std::uint64_t speculative_bytes_in_flight() const { return speculative_bytes_; }
  /// Bytes of all requests in flight (sent, not yet arrived).
  std::uint64_t requested_bytes_in_flight() const { return in_flight_bytes_; }
  /// The newest messages (at most settings.max_messages), oldest first.
  const std::deque<std::string>& errors() const { return errors_; }
  std::size_t error_count() const { return error_count_; }

 private:
  struct HeapEntry {
    double priority = 0;
    std::uint32_t level = 0;
    KeyframeId keyframe = no_keyframe;
    bool due = false;     ///< in the due window (priorities.hpp)
    bool hidden = false;  ///< of a node no ray reached: kept if resident, never requested
  };
  struct HeapLess {
    bool operator()(const HeapEntry& a, const HeapEntry& b) const {
      if (a.priority != b.priority) return a.priority < b.priority;
      if (a.level != b.level) return a.level > b.level;  // coarser first on ties
      return a.keyframe > b.keyframe;
    }
  };

  SpatialIndex index_;
  SchedulerSettings settings_;
  AtlasSlots atlas_;
  BrickLoader loader_;
  MinMaxHeap<HeapEntry, HeapLess> heap_;
  std::vector<HeapEntry> selection_;  ///< this frame's selected set, highest priority first
  std::vector<double> random_table_, temporal_;
  std::vector<DueTime> due_;                               ///< one node's due window
  std::vector<std::pair<double, std::uint32_t>> by_time_;  ///< held steps by priority part
  StoredTimes stored_times_;        ///< the selection's, kept from frame to frame (its memory)
  std::optional<double> built_at_;  ///< the last update's SVO build: its clock time
  LodBlendState blend_;             ///< level-of-detail blending's, kept from frame to frame
  std::vector<double> level_sse_;   ///< SseScope::level: per level, this frame
  PlayheadMotion motion_;
  /// Requests in flight: bytes and whether speculative (outside the due window when requested).
  struct InFlight {
    std::uint32_t bytes = 0;
    bool speculative = false;
  };
  std::unordered_map<KeyframeId, InFlight> in_flight_;
  std::uint64_t in_flight_bytes_ = 0, speculative_bytes_ = 0;
  ViewTraversal view_;
  ResidentKeyframes resident_;
  /// The ids of selection_, ascending, with their positions in it.
  std::vector<std::pair<KeyframeId, std::uint32_t>> selected_;
  static constexpr std::uint32_t no_slot = 0xFFFFFFFFu;
  std::vector<std::uint32_t> slot_of_;  ///< per selection_ entry: its atlas slot, or no_slot
  std::unordered_map<KeyframeId, BrickArrival> waiting_;  ///< arrived, not uploaded yet
  std::deque<std::string> errors_;
  std::size_t error_count_ = 0;
  std::vector<std::string> frame_errors_;

  // Ray-guided feedback. The last feedback_frames SVOs' regions (the spatial node each octant
  // drawn stands for, and its leaf record) and node records (spatial node, parent record), by GPU
  // frame; Algorithm 1's priorities per spatial node from the newest feedback, by its stamp.
  static constexpr std::int32_t priority_hidden = -(1 << 30);  ///< −∞: no ray reached it
  /// Subtracted from a hidden node's priorities: below every other's (they are O(sse_weight)).
  static constexpr double hidden_demotion = 1e6;
  static constexpr std::int32_t priority_unknown = 1 << 30;  ///< no feedback can tell
  static constexpr std::uint32_t no_entry = 0xFFFFFFFFu;     ///< a region of unknown reach
  struct SvoRegion {
    std::uint32_t record = 0, node = 0, entry = no_entry;  ///< entry: in the feedback table
  };
  struct KeptSvo {
    std::uint64_t gpu_frame = 0;
    std::vector<SvoRegion> regions;
    std::vector<std::uint32_t> record_nodes, record_parents;
    std::size_t leaf_count = 0;
  };
  std::deque<KeptSvo> kept_svos_;      ///< oldest first
  std::uint32_t priority_stamp_ = 0;   ///< counts feedback() calls
  std::uint32_t feedback_stamp_ = 0;   ///< the newest feedback's, 0: none (or forgotten)
  std::uint64_t feedback_frame_ = 0;   ///< the GPU frame it was drawn for
  std::uint64_t forgotten_frame_ = 0;  ///< forget_feedback(): tables of earlier frames refused
  std::vector<std::uint32_t> priority_stamps_;  ///< per spatial node
  std::vector<std::int32_t> ray_priority_;      ///< per spatial node
  std::vector<std::uint8_t> hidden_;            ///< per spatial node, this frame
  std::vector<std::uint32_t> hidden_list_;      ///< the nodes hidden_ marks
  std::vector<std::int32_t> record_priority_;   ///< scratch: per node record

  /// Whether feedback guides the selection: given, and its frame still one of the kept.
  bool feedback_current() const;
  /// The ray priority of a visited node (priority_unknown without current feedback).
  std::int32_t ray_priority(std::uint32_t node) const;
  /// Keeps the regions of an SVO just built for feedback(), for its GPU frame.
  void keep_svo_regions(const SvoArrays& svo, std::uint64_t gpu_frame_number);

  /// The selected set (Cesium patent [0060]–[0063]): the atlas's worth of keyframe nodes of the
  /// highest priority among the visible nodes' held ones, into selection_.
  void select(const player::OrbitCamera& camera, double playhead);
  bool selected(KeyframeId id) const;
  void add_error(std::string message);
  void end_request(KeyframeId id);
};

}  // namespace volreel::stream
