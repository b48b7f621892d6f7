// vrsync agent SDK: compatibility facade for agents written against the original
// UnityVR C++ client (AnnarProtoMain / AnnarProtoReceive / AnnarProtoSend), so that they
// port with few edits. The mapping is documented in agent-sdk/README.md.
//
//     #include <vrsync/compat.hpp>
//     using namespace vrsync::compat;
//
//     AnnarProtoMain main("config.toml", agentNo);       // was (addr, port, agentNo, ...)
//     AnnarProtoReceive* receiver = main.getReceiver();
//     AnnarProtoSend* sender = main.getSender();
//     for (int time = 0; time < maxTime; time++) {
//         while (!receiver->hasStartSyncReceivedAndResetState()) MSLEEP(1);
//         AnnarImage right, left;
//         receiver->getImageData(&right, &left);
//         ...
//         sender->sendAgentMovement(degree, distance);
//         sender->sendStopSync();
//     }
//
// Differences from the original: nothing runs in background threads (the poll reads
// shared memory directly), images are raw pixels (no PNG) and are views valid until
// sendStopSync() or the next hasStartSyncReceivedAndResetState(); when the
// host ends the run, hasStartSyncReceivedAndResetState() throws vrsync::compat::SessionClosed
// (catch it around the loop), and other failures throw vrsync::Error.
#ifndef VRSYNC_COMPAT_HPP
#define VRSYNC_COMPAT_HPP

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "agent.hpp"

#ifndef MSLEEP
/// The original's sleep macro, in milliseconds.
#define MSLEEP(ms) std::this_thread::sleep_for(std::chrono::milliseconds(ms))
#endif

namespace vrsync {
namespace compat {

/// Thrown by AnnarProtoReceive::hasStartSyncReceivedAndResetState() when the host
/// closed the session (the run is over): the original loop would spin forever.
class SessionClosed : public Error {
public:
    SessionClosed() : Error(VRS_SESSION_CLOSED, "the host closed the session") {}
};

/// Action states as in the original MsgActionExecutationStatus.
enum ActionExecState : int {
    InExecution = VRS_ACTION_IN_EXECUTION,
    Finished = VRS_ACTION_FINISHED,
    Aborted = VRS_ACTION_ABORTED,
    Walking = VRS_ACTION_WALKING,
    Rotating = VRS_ACTION_ROTATING,
    WalkingRotating = VRS_ACTION_WALKING_ROTATING,
};

/// An image, as the original AnnarImage, but a view: raw pixels in shared memory (no PNG,
/// no copy), valid until sendStopSync() or the next hasStartSyncReceivedAndResetState().
class AnnarImage {
public:
    AnnarImage() = default;
    /// An image that save() writes to `filename`.
    explicit AnnarImage(std::string filename) : filename_(std::move(filename)) {}

    bool valid() const noexcept { return image_.data() != nullptr; }
    const std::uint8_t* data() const noexcept { return image_.data(); }
    std::size_t size() const noexcept { return image_.size(); }
    int getWidth() const noexcept { return static_cast<int>(image_.width()); }
    int getHeight() const noexcept { return static_cast<int>(image_.height()); }
    std::size_t stride() const noexcept { return image_.stride(); }
    PixelFormat format() const noexcept { return image_.format(); }
    const Image& view() const noexcept { return image_; }

    /// Writes the image to the filename given at construction (binary PPM for rgb8/rgba8,
    /// PGM for gray8). Returns false on failure or for depth images.
    bool save() const { return save(filename_); }
    /// Writes the image to `filename` (see save()).
    bool save(const std::string& filename) const {
        if (!valid() || filename.empty() || image_.format() == VRS_PIXEL_FORMAT_DEPTH32F) {
            return false;
        }
        const bool gray = image_.format() == VRS_PIXEL_FORMAT_GRAY8;
        std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(filename.c_str(), "wb"),
                                                          &std::fclose);
        if (!f) return false;
        std::fprintf(f.get(), "%s\n%u %u\n255\n", gray ? "P5" : "P6", image_.width(),
                     image_.height());
        const std::size_t bpp = image_.bytes_per_pixel();
        for (std::uint32_t y = 0; y < image_.height(); ++y) {
            const std::uint8_t* row = image_.row(y);
            if (bpp == 4) {  // rgba8: drop alpha
                for (std::uint32_t x = 0; x < image_.width(); ++x) {
                    if (std::fwrite(row + 4 * x, 1, 3, f.get()) != 3) return false;
                }
            } else if (std::fwrite(row, 1, image_.width() * bpp, f.get()) !=
                       image_.width() * bpp) {
                return false;
            }
        }
        return true;
    }

private:
    friend class AnnarProtoReceive;
    Image image_;
    std::string filename_;
};

/// The receiving side (the original AnnarProtoReceive).
class AnnarProtoReceive {
public:
    /// Non-blocking: true once per new sensor frame (start sync), which then becomes the
    /// frame the get* functions read. Keeps the original polling loop working unchanged:
    ///     while (!receiver->hasStartSyncReceivedAndResetState()) MSLEEP(1);
    /// Throws SessionClosed when the run is over, vrsync::Error when the host is gone.
    bool hasStartSyncReceivedAndResetState() {
        return waitForStartSync(std::chrono::milliseconds(0));
    }

    /// Blocking variant (not in the original): waits up to `timeout` for the next frame.
    bool waitForStartSync(std::chrono::milliseconds timeout) {
        // Any wait ends the current frame in the library: drop our views of it first.
        frame_ = Frame();
        std::optional<Frame> f = agent_->try_wait_start(timeout);
        if (!f) return false;
        if (!*f) throw SessionClosed();
        frame_ = std::move(*f);
        return true;
    }

    /// The right and left eye images of the current frame (cameras "right" and "left",
    /// else the first two cameras). Either pointer may be null. False without a frame.
    bool getImageData(AnnarImage* right, AnnarImage* left) const {
        if (!frame_) return false;
        const Image* r = frame_.find_image("right");
        const Image* l = frame_.find_image("left");
        const View<Image> all = frame_.images();
        if (l == nullptr && all.size() > 0) l = &all[0];
        if (r == nullptr && all.size() > 1) r = &all[1];
        if ((right != nullptr && r == nullptr) || (left != nullptr && l == nullptr)) {
            return false;
        }
        if (right != nullptr) right->image_ = *r;
        if (left != nullptr) left->image_ = *l;
        return true;
    }

    /// Any camera by name (e.g. the later "main" image). False if there is none.
    bool getImageData(const std::string& camera, AnnarImage* out) const {
        if (!frame_ || out == nullptr) return false;
        const Image* img = frame_.find_image(camera);
        if (img == nullptr) return false;
        out->image_ = *img;
        return true;
    }

    /// Grid position sensor: position x, y, z.
    bool getGridsensorData(float& x, float& y, float& z) const {
        if (!frame_) return false;
        x = frame_.grid().position[0];
        y = frame_.grid().position[1];
        z = frame_.grid().position[2];
        return true;
    }

    /// Grid position sensor: position and Euler rotation in degrees.
    bool getGridsensorData(float& x, float& y, float& z, float& rotX, float& rotY,
                           float& rotZ) const {
        if (!getGridsensorData(x, y, z)) return false;
        rotX = frame_.grid().rotation_deg[0];
        rotY = frame_.grid().rotation_deg[1];
        rotZ = frame_.grid().rotation_deg[2];
        return true;
    }

    /// The latest action status of the current frame (as the original: the newest one).
    /// False when the frame reports none.
    bool getActionExecState(int& id, int& state) const {
        if (!frame_ || frame_.statuses().empty()) return false;
        const ActionStatus& s = frame_.statuses()[frame_.statuses().size() - 1];
        id = static_cast<int>(s.action_id);
        state = static_cast<int>(s.state);
        return true;
    }

    /// The status of action `id` in the current frame (the Python client's
    /// checkActionExecState(id)). False when the frame does not report it.
    bool getActionExecStateFor(int id, int& state) const {
        if (!frame_) return false;
        bool found = false;
        for (const ActionStatus& s : frame_.statuses()) {
            if (static_cast<int>(s.action_id) == id) {
                state = static_cast<int>(s.state);
                found = true;
            }
        }
        return found;
    }

    /// The first collision of the current frame.
    bool getCollision(int& actionId, int& colliderId) const {
        if (!frame_ || frame_.collisions().empty()) return false;
        actionId = static_cast<int>(frame_.collisions()[0].action_id);
        colliderId = static_cast<int>(frame_.collisions()[0].collider_id);
        return true;
    }

    /// Head motion sensor (velocity, acceleration, angular velocity and acceleration).
    bool getHeadMotion(HeadMotion& out) const {
        if (!frame_) return false;
        out = frame_.head_motion();
        return true;
    }

    /// Eye position sensor.
    bool getEyePosition(EyePosition& out) const {
        if (!frame_) return false;
        out = frame_.eye();
        return true;
    }

    /// Reward received since the previous frame.
    bool getExternalReward(float& reward) const {
        if (!frame_) return false;
        reward = frame_.reward();
        return true;
    }

    /// The whole current frame (cycle, simulated time, pose, ...); empty before the
    /// first start sync and after sendStopSync().
    const Frame& frame() const noexcept { return frame_; }

private:
    friend class AnnarProtoMain;
    friend class AnnarProtoSend;
    explicit AnnarProtoReceive(Agent* agent) : agent_(agent) {}
    Agent* agent_;
    Frame frame_;
};

/// The sending side (the original AnnarProtoSend). Each send* queues one command and
/// returns its action id (statuses quote it); sendStopSync() sends them all with the stop.
class AnnarProtoSend {
public:
    int sendAgentMovement(float degree, float distance) {
        return id(agent_->send_move(degree, distance));
    }
    int sendAgentTurn(float degree) { return id(agent_->send_turn(degree)); }
    /// targetMode is accepted for compatibility and ignored (as the original's VR did).
    int sendAgentMoveTo(float x, float y, float z, int targetMode = 0) {
        (void)targetMode;
        return id(agent_->send_move_to(x, y, z));
    }
    int sendAgentCancelMovement() { return id(agent_->send_cancel_move()); }
    int sendEyeMovement(float panLeft, float panRight, float tilt) {
        return id(agent_->send_eye_movement(panLeft, panRight, tilt));
    }
    int sendEyeFixation(float x, float y, float z) {
        return id(agent_->send_eye_fixation(x, y, z));
    }
    int sendGraspID(int objectId) { return id(agent_->send_grasp_id(uid(objectId))); }
    int sendGraspPos(float x, float y) { return id(agent_->send_grasp_pos(x, y)); }
    int sendPointID(int objectId) { return id(agent_->send_point_id(uid(objectId))); }
    int sendPointPos(float x, float y) { return id(agent_->send_point_pos(x, y)); }
    int sendInteractionID(int objectId) { return id(agent_->send_interact_id(uid(objectId))); }
    int sendInteractionPos(float x, float y) { return id(agent_->send_interact_pos(x, y)); }
    int sendGraspRelease() { return id(agent_->send_grasp_release()); }
    int sendEnvironmentReset(int type = 0) {
        return id(agent_->send_environment_reset(uid(type)));
    }
    int sendTrialReset(int type = 0) { return id(agent_->send_trial_reset(uid(type))); }
    /// Ends the cycle: sends the queued commands with the stop. The receiver's current
    /// frame (and its images) ends here. If the host already ended the run, the next
    /// hasStartSyncReceivedAndResetState() throws SessionClosed.
    void sendStopSync() {
        receiver_->frame_ = Frame();
        agent_->stop();
    }

private:
    friend class AnnarProtoMain;
    AnnarProtoSend(Agent* agent, AnnarProtoReceive* receiver)
        : agent_(agent), receiver_(receiver) {}
    static int id(std::uint32_t action_id) noexcept { return static_cast<int>(action_id); }
    static std::uint32_t uid(int value) {
        if (value < 0) {
            throw Error(VRS_ERROR_INVALID_ARGUMENT,
                        "ids and reset types must be >= 0, got " + std::to_string(value));
        }
        return static_cast<std::uint32_t>(value);
    }
    Agent* agent_;
    AnnarProtoReceive* receiver_;
};

/// The connection (the original AnnarProtoMain(srv_addr, remotePort, agentNo, agentOnly)):
/// the config file replaces address and port, as the host reads the same file.
/// Not copyable or movable (the receiver and sender point into it).
class AnnarProtoMain {
public:
    /// Connects agent `agentNo`; throws vrsync::Error.
    AnnarProtoMain(const std::string& configPath, int agentNo,
                   std::chrono::milliseconds connectTimeout = std::chrono::milliseconds(-1))
        : agent_(configPath, checkedAgentNo(agentNo), connectTimeout),
          receiver_(&agent_),
          sender_(&agent_, &receiver_) {}
    AnnarProtoMain(const AnnarProtoMain&) = delete;
    AnnarProtoMain& operator=(const AnnarProtoMain&) = delete;

    /// Kept for compatibility: connecting already happened in the constructor.
    void start() noexcept {}
    AnnarProtoReceive* getReceiver() noexcept { return &receiver_; }
    AnnarProtoSend* getSender() noexcept { return &sender_; }
    /// The underlying vrsync::Agent.
    Agent& agent() noexcept { return agent_; }

private:
    static std::uint32_t checkedAgentNo(int agentNo) {
        if (agentNo < 0) {
            throw Error(VRS_ERROR_INVALID_ARGUMENT,
                        "agent number must be >= 0, got " + std::to_string(agentNo));
        }
        return static_cast<std::uint32_t>(agentNo);
    }
    Agent agent_;
    AnnarProtoReceive receiver_;
    AnnarProtoSend sender_;
};

}  // namespace compat
}  // namespace vrsync

#endif  // VRSYNC_COMPAT_HPP
