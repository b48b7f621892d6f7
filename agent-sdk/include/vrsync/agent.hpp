// vrsync agent SDK: C++17 header-only wrapper over the C ABI in vrsync.h.
//
//     #include <vrsync/agent.hpp>
//     using namespace std::chrono_literals;
//
//     vrsync::Agent agent("config.toml", 0);        // connects (throws vrsync::Error)
//     while (vrsync::Frame frame = agent.wait_start()) {      // empty frame: run over
//         const vrsync::Image& left = frame.image("left");     // a view into shared memory
//         ... left.data(), left.width(), left.height(), left.stride() ...
//         vrsync::View<float> joints = frame.vector("joints"); // [[agent.vector]], no copy
//         agent.send_move(90.0f, 1.0f);
//         agent.act("torque", {0.1f, -0.2f});        // [[agent.action]] (continuous)
//         agent.act_discrete("gear", 2);             // [[agent.action]] (discrete)
//         agent.stop();                              // ends the cycle and the frame
//     }
//
// Lifetimes: a Frame, its Images and its vectors are views. They stay valid until the next
// wait_start()/try_wait_start(), stop() or the end of the Agent, whichever comes first.
// Threads: an Agent belongs to the thread that constructed it (calls from another thread
// throw an Error with status VRS_ERROR_WRONG_THREAD).
// Link: libvrsync_agent (CMake: find_package(vrsync) + vrsync::agent; pkg-config: vrsync).
#ifndef VRSYNC_AGENT_HPP
#define VRSYNC_AGENT_HPP

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <initializer_list>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

#include "../vrsync.h"

namespace vrsync {

/// Status codes of the C ABI.
using Status = vrs_status_t;
/// Pixel formats.
using PixelFormat = vrs_pixel_format_t;
/// Body pose: position[3] in metres, rotation[4] quaternion x, y, z, w.
using Pose = vrs_pose_t;
/// Grid position sensor.
using GridPosition = vrs_grid_position_t;
/// Head motion sensor.
using HeadMotion = vrs_head_motion_t;
/// Eye position sensor.
using EyePosition = vrs_eye_position_t;
/// An action status (action_id, state: a vrs_action_state_t value).
using ActionStatus = vrs_action_status_t;
/// A collision (action_id, collider_id).
using Collision = vrs_collision_t;
/// A command of any kind, for Agent::send().
using Command = vrs_command_t;
/// Continuous (VRS_ACTION_KIND_BOX) or discrete (VRS_ACTION_KIND_DISCRETE) action.
using ActionKind = vrs_action_kind_t;

/// The library version, e.g. "0.1.0".
inline const char* version() noexcept { return vrs_version(); }

/// Sends the library's log to stderr: `filter` is a RUST_LOG-style filter ("info",
/// "vrsync_agent=debug"); nullptr uses the RUST_LOG environment variable, else "warn".
/// Returns false if the filter is invalid or logging was already set up.
inline bool init_logging(const char* filter = nullptr) noexcept {
    return vrs_init_logging(filter) == VRS_OK;
}

/// A failed call: the C ABI status and the library's message.
class Error : public std::runtime_error {
public:
    Error(Status status, const std::string& message)
        : std::runtime_error(message), status_(status) {}
    /// The status code (VRS_TIMEOUT for a timeout, a negative VRS_ERROR_* otherwise).
    Status status() const noexcept { return status_; }
    /// The status name, e.g. "VRS_ERROR_HOST_GONE".
    const char* status_name() const noexcept { return vrs_status_name(status_); }

private:
    Status status_;
};

namespace detail {
inline void check(Status status, const char* what) {
    if (status != VRS_OK) {
        throw Error(status, std::string(what) + ": " + vrs_last_error_message());
    }
}
inline std::int64_t to_ms(std::chrono::milliseconds t) noexcept {
    return static_cast<std::int64_t>(t.count());
}
}  // namespace detail

/// Minimal read-only view of a contiguous array (C++17 has no std::span).
template <class T>
class View {
public:
    constexpr View() noexcept = default;
    constexpr View(const T* first, std::size_t count) noexcept : first_(first), count_(count) {}
    constexpr const T* data() const noexcept { return first_; }
    constexpr const T* begin() const noexcept { return first_; }
    constexpr const T* end() const noexcept { return first_ + count_; }
    constexpr std::size_t size() const noexcept { return count_; }
    constexpr bool empty() const noexcept { return count_ == 0; }
    constexpr const T& operator[](std::size_t i) const noexcept { return first_[i]; }

private:
    const T* first_ = nullptr;
    std::size_t count_ = 0;
};

/// One image of a frame: a view into shared memory (no copy). Rows are stride() bytes
/// apart, origin top-left.
class Image {
public:
    Image() noexcept : raw_{} {}
    explicit Image(const vrs_image_t& raw) noexcept : raw_(raw) {}
    /// First byte of the first row.
    const std::uint8_t* data() const noexcept { return raw_.data; }
    /// Bytes at data() (stride() * height()).
    std::size_t size() const noexcept { return raw_.len; }
    std::uint32_t width() const noexcept { return raw_.width; }
    std::uint32_t height() const noexcept { return raw_.height; }
    /// Bytes per row.
    std::size_t stride() const noexcept { return raw_.stride; }
    PixelFormat format() const noexcept { return raw_.format; }
    /// Bytes per pixel of format().
    std::size_t bytes_per_pixel() const noexcept {
        switch (raw_.format) {
            case VRS_PIXEL_FORMAT_GRAY8: return 1;
            case VRS_PIXEL_FORMAT_RGB8: return 3;
            default: return 4;
        }
    }
    /// Row y (stride() bytes); y must be < height().
    const std::uint8_t* row(std::uint32_t y) const noexcept { return raw_.data + y * raw_.stride; }
    /// The camera name ("left", "right", ...).
    std::string_view name() const noexcept { return std::string_view(raw_.name); }
    /// Index of the camera in the agent's camera list.
    std::uint32_t camera() const noexcept { return raw_.camera; }
    /// The C description.
    const vrs_image_t& raw() const noexcept { return raw_; }

private:
    vrs_image_t raw_;
};

/// One vector ([[agent.vector]]) of this agent as its config declares it: name, length and
/// observation bounds (-inf/+inf where the config gives none). Valid while the Agent lives.
class VectorSpec {
public:
    explicit VectorSpec(const vrs_vector_spec_t& raw) noexcept : raw_(raw) {}
    std::string_view name() const noexcept { return std::string_view(raw_.name); }
    /// Number of values.
    std::size_t size() const noexcept { return raw_.len; }
    View<float> low() const noexcept { return View<float>(raw_.low, raw_.len); }
    View<float> high() const noexcept { return View<float>(raw_.high, raw_.len); }
    /// Index in the agent's vector list.
    std::uint32_t index() const noexcept { return raw_.index; }
    const vrs_vector_spec_t& raw() const noexcept { return raw_; }

private:
    vrs_vector_spec_t raw_;
};

/// One action ([[agent.action]]) of this agent as its config declares it: continuous
/// (size() floats within low() and high()) or discrete (a choice in 0..n()). Valid while
/// the Agent lives.
class ActionSpec {
public:
    explicit ActionSpec(const vrs_action_spec_t& raw) noexcept : raw_(raw) {}
    std::string_view name() const noexcept { return std::string_view(raw_.name); }
    ActionKind kind() const noexcept { return raw_.kind; }
    bool is_discrete() const noexcept { return raw_.kind == VRS_ACTION_KIND_DISCRETE; }
    /// Continuous: number of floats; discrete: 0.
    std::size_t size() const noexcept { return raw_.len; }
    /// Discrete: number of choices; continuous: 0.
    std::uint32_t n() const noexcept { return raw_.n; }
    /// Continuous: the lower bounds; discrete: empty.
    View<float> low() const noexcept { return View<float>(raw_.low, raw_.len); }
    /// Continuous: the upper bounds; discrete: empty.
    View<float> high() const noexcept { return View<float>(raw_.high, raw_.len); }
    /// Index in the agent's action list.
    std::uint32_t index() const noexcept { return raw_.index; }
    const vrs_action_spec_t& raw() const noexcept { return raw_; }

private:
    vrs_action_spec_t raw_;
};

/// A sensor frame: scalar sensors copied, images and vectors as views into shared memory.
/// An empty frame (false in a condition) means the host closed the session.
class Frame {
public:
    /// An empty frame.
    Frame() noexcept : raw_{}, valid_(false) {}

    /// Whether this holds a frame (false: the session is closed).
    explicit operator bool() const noexcept { return valid_; }

    std::uint64_t cycle() const noexcept { return raw_.cycle; }
    /// Simulated time at the start of this cycle.
    std::chrono::nanoseconds sim_time() const noexcept {
        return std::chrono::nanoseconds(static_cast<std::int64_t>(raw_.sim_time_ns));
    }
    const Pose& pose() const noexcept { return raw_.pose; }
    float reward() const noexcept { return raw_.reward; }
    const GridPosition& grid() const noexcept { return raw_.grid; }
    const HeadMotion& head_motion() const noexcept { return raw_.head_motion; }
    const EyePosition& eye() const noexcept { return raw_.eye; }
    bool sync_mode() const noexcept { return raw_.sync_mode; }
    /// How this agent's previous cycle ended.
    vrs_outcome_t previous_outcome() const noexcept { return raw_.previous_outcome; }
    /// How many of this agent's commands the host rejected in the previous cycle.
    std::uint32_t previous_rejected() const noexcept { return raw_.previous_rejected; }

    /// All images, in camera order.
    View<Image> images() const noexcept { return View<Image>(images_.data(), raw_.image_count); }
    /// Image i; throws Error (VRS_ERROR_OUT_OF_RANGE) past the end.
    const Image& image(std::size_t i) const {
        if (i >= raw_.image_count) {
            throw Error(VRS_ERROR_OUT_OF_RANGE, "image index " + std::to_string(i) +
                                                    " is out of range (the frame has " +
                                                    std::to_string(raw_.image_count) + ")");
        }
        return images_[i];
    }
    /// The image of the camera called name, or nullptr.
    const Image* find_image(std::string_view name) const noexcept {
        for (const Image& img : images()) {
            if (img.name() == name) return &img;
        }
        return nullptr;
    }
    /// The image of the camera called name; throws Error if there is none.
    const Image& image(std::string_view name) const {
        if (const Image* img = find_image(name)) return *img;
        throw Error(VRS_ERROR_INVALID_ARGUMENT,
                    "the frame has no camera named \"" + std::string(name) + "\"");
    }
    /// Action statuses this frame brings: each exactly once, also those of frames the
    /// agent skipped (the host repeats them until a stop acknowledges them).
    View<ActionStatus> statuses() const noexcept {
        return View<ActionStatus>(statuses_.data(), raw_.status_count);
    }
    /// Collisions this frame brings, each exactly once.
    View<Collision> collisions() const noexcept {
        return View<Collision>(collisions_.data(), raw_.collision_count);
    }
    /// Number of vectors ([[agent.vector]], config order).
    std::size_t vector_count() const noexcept { return vector_count_; }
    /// Vector i (config order), a view into shared memory; throws Error
    /// (VRS_ERROR_OUT_OF_RANGE) past the end.
    View<float> vector(std::size_t i) const {
        if (i >= vector_count_) {
            throw Error(VRS_ERROR_OUT_OF_RANGE, "vector index " + std::to_string(i) +
                                                    " is out of range (the frame has " +
                                                    std::to_string(vector_count_) + ")");
        }
        return View<float>(vectors_[i].data, vectors_[i].len);
    }
    /// The vector called name, or std::nullopt.
    std::optional<View<float>> find_vector(std::string_view name) const noexcept {
        for (std::size_t i = 0; i < vector_count_; ++i) {
            if (std::string_view(vectors_[i].name) == name) {
                return View<float>(vectors_[i].data, vectors_[i].len);
            }
        }
        return std::nullopt;
    }
    /// The vector called name, a view into shared memory (no copy); throws Error
    /// (VRS_ERROR_UNKNOWN_CHANNEL) if the agent has none of that name.
    View<float> vector(std::string_view name) const {
        if (std::optional<View<float>> v = find_vector(name)) return *v;
        throw Error(VRS_ERROR_UNKNOWN_CHANNEL,
                    "the frame has no vector named \"" + std::string(name) + "\"");
    }
    /// The C frame description.
    const vrs_frame_t& raw() const noexcept { return raw_; }

private:
    friend class Agent;
    vrs_frame_t raw_;
    bool valid_;
    std::array<Image, VRS_MAX_IMAGES> images_{};
    std::array<ActionStatus, VRS_MAX_STATUSES> statuses_{};
    std::array<Collision, VRS_MAX_COLLISIONS> collisions_{};
    std::array<vrs_vector_t, VRS_MAX_VECTORS> vectors_{};
    std::size_t vector_count_ = 0;
};

/// A connected agent: move-only, disconnects on destruction.
class Agent {
public:
    /// Connects agent `id` using the config file at `config_path` (the file the host
    /// uses), waiting up to `connect_timeout` for the host (negative: the config's
    /// connect_timeout). Throws Error.
    Agent(const std::string& config_path, std::uint32_t id,
          std::chrono::milliseconds connect_timeout = std::chrono::milliseconds(-1)) {
        detail::check(vrs_agent_connect(config_path.c_str(), id,
                                        detail::to_ms(connect_timeout), &handle_),
                      "vrs_agent_connect");
        detail::check(vrs_agent_channel_counts(handle_, &vector_count_, &action_count_),
                      "vrs_agent_channel_counts");
    }
    /// Leaves the session gracefully (vrs_agent_disconnect): the host is told at once.
    ~Agent() { reset(); }
    Agent(const Agent&) = delete;
    Agent& operator=(const Agent&) = delete;
    Agent(Agent&& other) noexcept
        : handle_(std::exchange(other.handle_, nullptr)),
          vector_count_(other.vector_count_),
          action_count_(other.action_count_) {}
    Agent& operator=(Agent&& other) noexcept {
        if (this != &other) {
            reset();
            handle_ = std::exchange(other.handle_, nullptr);
            vector_count_ = other.vector_count_;
            action_count_ = other.action_count_;
        }
        return *this;
    }

    /// This agent's id.
    std::uint32_t id() const {
        std::uint32_t id = 0;
        detail::check(vrs_agent_id(handle(), &id), "vrs_agent_id");
        return id;
    }
    /// The latest status (a vrs_action_state_t value) a frame brought for action_id, if
    /// any (the original client's status map; the latest 1024 actions are kept).
    std::optional<std::uint32_t> action_state(std::uint32_t action_id) const {
        std::uint32_t state = 0;
        bool known = false;
        detail::check(vrs_agent_action_state(handle(), action_id, &state, &known),
                      "vrs_agent_action_state");
        if (!known) return std::nullopt;
        return state;
    }

    /// Blocks until the host signals start with a new frame, up to `timeout`. Returns an
    /// empty frame when the host closed the session (the run is over). Throws Error on a
    /// timeout (status VRS_TIMEOUT), a dead host, a protocol error or SIGINT/SIGTERM.
    Frame wait_start(std::chrono::milliseconds timeout) { return wait(detail::to_ms(timeout)); }

    /// Like wait_start(timeout) without a time limit (a dead host is still detected).
    Frame wait_start() { return wait(-1); }

    /// Non-blocking (timeout 0) or short wait: std::nullopt when no new frame arrived in
    /// time, an empty Frame when the session is closed, else the frame.
    std::optional<Frame> try_wait_start(
        std::chrono::milliseconds timeout = std::chrono::milliseconds(0)) {
        Frame frame;
        Status st = vrs_agent_wait_start(handle(), detail::to_ms(timeout), &frame.raw_);
        if (st == VRS_TIMEOUT) return std::nullopt;
        return finish(st, frame);
    }

    // Typed commands; each returns the action id that statuses and collisions quote.
    /// Walk towards heading_deg (world frame, 0..360) for distance_m metres.
    std::uint32_t send_move(float heading_deg, float distance_m) {
        return sent(vrs_agent_send_move(handle(), heading_deg, distance_m, &id_), "send_move");
    }
    /// Turn in place by angle_deg (positive: clockwise seen from above).
    std::uint32_t send_turn(float angle_deg) {
        return sent(vrs_agent_send_turn(handle(), angle_deg, &id_), "send_turn");
    }
    /// Walk in a straight line to the world position (x, y, z).
    std::uint32_t send_move_to(float x, float y, float z) {
        return sent(vrs_agent_send_move_to(handle(), x, y, z, &id_), "send_move_to");
    }
    /// Cancel the running movement.
    std::uint32_t send_cancel_move() {
        return sent(vrs_agent_send_cancel_move(handle(), &id_), "send_cancel_move");
    }
    /// Move the eyes (degrees).
    std::uint32_t send_eye_movement(float pan_left_deg, float pan_right_deg, float tilt_deg) {
        return sent(vrs_agent_send_eye_movement(handle(), pan_left_deg, pan_right_deg, tilt_deg,
                                                &id_),
                    "send_eye_movement");
    }
    /// Fixate both eyes on the world point (x, y, z).
    std::uint32_t send_eye_fixation(float x, float y, float z) {
        return sent(vrs_agent_send_eye_fixation(handle(), x, y, z, &id_), "send_eye_fixation");
    }
    /// Grasp the object object_id.
    std::uint32_t send_grasp_id(std::uint32_t object_id) {
        return sent(vrs_agent_send_grasp_id(handle(), object_id, &id_), "send_grasp_id");
    }
    /// Grasp what is seen at left-eye pixel (x_px, y_px).
    std::uint32_t send_grasp_pos(float x_px, float y_px) {
        return sent(vrs_agent_send_grasp_pos(handle(), x_px, y_px, &id_), "send_grasp_pos");
    }
    /// Point at the object object_id.
    std::uint32_t send_point_id(std::uint32_t object_id) {
        return sent(vrs_agent_send_point_id(handle(), object_id, &id_), "send_point_id");
    }
    /// Point at left-eye pixel (x_px, y_px).
    std::uint32_t send_point_pos(float x_px, float y_px) {
        return sent(vrs_agent_send_point_pos(handle(), x_px, y_px, &id_), "send_point_pos");
    }
    /// Interact with the object object_id.
    std::uint32_t send_interact_id(std::uint32_t object_id) {
        return sent(vrs_agent_send_interact_id(handle(), object_id, &id_), "send_interact_id");
    }
    /// Interact with what is seen at left-eye pixel (x_px, y_px).
    std::uint32_t send_interact_pos(float x_px, float y_px) {
        return sent(vrs_agent_send_interact_pos(handle(), x_px, y_px, &id_), "send_interact_pos");
    }
    /// Release the grasped object.
    std::uint32_t send_grasp_release() {
        return sent(vrs_agent_send_grasp_release(handle(), &id_), "send_grasp_release");
    }
    /// Reset the environment.
    std::uint32_t send_environment_reset(std::uint32_t reset_type = 0) {
        return sent(vrs_agent_send_environment_reset(handle(), reset_type, &id_),
                    "send_environment_reset");
    }
    /// Reset the trial.
    std::uint32_t send_trial_reset(std::uint32_t reset_type = 0) {
        return sent(vrs_agent_send_trial_reset(handle(), reset_type, &id_), "send_trial_reset");
    }
    /// Any command, with a fresh action id.
    std::uint32_t send(const Command& command) {
        return sent(vrs_agent_send(handle(), &command, &id_), "send");
    }
    /// Any command, with an action id of your choice.
    void send_with_id(std::uint32_t action_id, const Command& command) {
        detail::check(vrs_agent_send_with_id(handle(), action_id, &command), "send_with_id");
    }

    // Channels ([[agent.vector]], [[agent.action]]).
    /// Number of vectors this agent's frames carry.
    std::size_t vector_count() const noexcept { return vector_count_; }
    /// Number of actions this agent may send.
    std::size_t action_count() const noexcept { return action_count_; }
    /// Vector i as the config declares it. Throws Error (VRS_ERROR_OUT_OF_RANGE).
    VectorSpec vector_spec(std::size_t i) const {
        vrs_vector_spec_t raw;
        detail::check(vrs_agent_vector_spec(handle(), i, &raw), "vrs_agent_vector_spec");
        return VectorSpec(raw);
    }
    /// Action i as the config declares it. Throws Error (VRS_ERROR_OUT_OF_RANGE).
    ActionSpec action_spec(std::size_t i) const {
        vrs_action_spec_t raw;
        detail::check(vrs_agent_action_spec(handle(), i, &raw), "vrs_agent_action_spec");
        return ActionSpec(raw);
    }
    /// Queues the value of the continuous action `name` for this cycle (it goes with the
    /// next stop(); the host takes the last value of a cycle). Throws Error naming the
    /// action: VRS_ERROR_UNKNOWN_CHANNEL, VRS_ERROR_WRONG_LENGTH, VRS_ERROR_OUT_OF_BOUNDS,
    /// VRS_ERROR_WRONG_ACTION_KIND, VRS_ERROR_QUEUE_FULL (nothing is queued then).
    void act(const std::string& name, const float* values, std::size_t len) {
        detail::check(vrs_agent_act(handle(), name.c_str(), values, len), "vrs_agent_act");
    }
    /// act() with a View, std::vector<float>, std::array<float, N>, …
    template <class Floats>
    auto act(const std::string& name, const Floats& values)
        -> decltype(static_cast<const float*>(values.data()), values.size(), void()) {
        act(name, values.data(), values.size());
    }
    /// act() with a braced list: agent.act("torque", {0.1f, -0.2f}).
    void act(const std::string& name, std::initializer_list<float> values) {
        act(name, values.begin(), values.size());
    }
    /// Queues the choice (0..n) of the discrete action `name` for this cycle. Throws Error
    /// naming the action: VRS_ERROR_UNKNOWN_CHANNEL, VRS_ERROR_CHOICE_OUT_OF_RANGE,
    /// VRS_ERROR_WRONG_ACTION_KIND, VRS_ERROR_QUEUE_FULL.
    void act_discrete(const std::string& name, std::uint32_t choice) {
        detail::check(vrs_agent_act_discrete(handle(), name.c_str(), choice),
                      "vrs_agent_act_discrete");
    }

    /// Ends this agent's cycle: sends the queued commands with the stop. The current
    /// frame (and its image views) ends here. Returns false if the host had already
    /// closed the session (the next wait_start() returns an empty frame). Throws Error.
    bool stop() {
        const Status st = vrs_agent_stop(handle());
        if (st == VRS_SESSION_CLOSED) return false;
        detail::check(st, "vrs_agent_stop");
        return true;
    }

    /// The C handle (for calls the wrapper does not cover).
    vrs_agent_t* handle() const {
        if (handle_ == nullptr) {
            throw Error(VRS_ERROR_INVALID_HANDLE, "vrsync::Agent was moved from");
        }
        return handle_;
    }

private:
    Frame wait(std::int64_t timeout_ms) {
        Frame frame;
        Status st = vrs_agent_wait_start(handle(), timeout_ms, &frame.raw_);
        return finish(st, frame);
    }

    Frame finish(Status st, Frame& frame) {
        if (st == VRS_SESSION_CLOSED) return Frame();
        detail::check(st, "vrs_agent_wait_start");
        frame.valid_ = true;
        for (std::uint32_t i = 0; i < frame.raw_.image_count && i < VRS_MAX_IMAGES; ++i) {
            vrs_image_t raw;
            detail::check(vrs_agent_image(handle_, i, &raw), "vrs_agent_image");
            frame.images_[i] = Image(raw);
        }
        for (std::uint32_t i = 0; i < frame.raw_.status_count && i < VRS_MAX_STATUSES; ++i) {
            detail::check(vrs_agent_status(handle_, i, &frame.statuses_[i]), "vrs_agent_status");
        }
        for (std::uint32_t i = 0; i < frame.raw_.collision_count && i < VRS_MAX_COLLISIONS; ++i) {
            detail::check(vrs_agent_collision(handle_, i, &frame.collisions_[i]),
                          "vrs_agent_collision");
        }
        frame.vector_count_ = 0;
        for (std::uint32_t i = 0; i < vector_count_ && i < VRS_MAX_VECTORS; ++i) {
            detail::check(vrs_agent_vector(handle_, i, &frame.vectors_[i]), "vrs_agent_vector");
            frame.vector_count_ = i + 1;
        }
        return std::move(frame);
    }

    std::uint32_t sent(Status st, const char* what) {
        detail::check(st, what);
        return id_;
    }

    void reset() noexcept {
        if (handle_ != nullptr) {
            vrs_agent_disconnect(handle_);
            handle_ = nullptr;
        }
    }

    vrs_agent_t* handle_ = nullptr;
    std::uint32_t id_ = 0;
    std::uint32_t vector_count_ = 0;
    std::uint32_t action_count_ = 0;
};

}  // namespace vrsync

#endif  // VRSYNC_AGENT_HPP
