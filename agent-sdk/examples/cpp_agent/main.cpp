// A vrsync agent in C++ with vrsync/agent.hpp: the original loop, blocking wait.
//
// usage: cpp_agent CONFIG AGENT_ID
// Looks at both eyes without copying them, walks towards the brighter side every 10
// cycles and turns a little in between.
// Exit codes: 0 when the host closed the session, 1 on failure, 2 on bad usage.
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>

#include <vrsync/agent.hpp>

namespace {

// Mean of the first channel over the image, read in place in shared memory.
double brightness(const vrsync::Image& img) {
    std::uint64_t sum = 0;
    const std::size_t bpp = img.bytes_per_pixel();
    for (std::uint32_t y = 0; y < img.height(); ++y) {
        const std::uint8_t* row = img.row(y);
        for (std::uint32_t x = 0; x < img.width(); ++x) sum += row[x * bpp];
    }
    const double n = static_cast<double>(img.width()) * img.height();
    return n > 0 ? static_cast<double>(sum) / n : 0.0;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: %s CONFIG AGENT_ID\n", argv[0]);
        return 2;
    }
    const auto id = static_cast<std::uint32_t>(std::strtoul(argv[2], nullptr, 10));
    vrsync::init_logging();  // the library's log on stderr, filtered by RUST_LOG
    try {
        vrsync::Agent agent(argv[1], id);
        std::fprintf(stderr, "cpp_agent %u: connected (vrsync %s)\n", id, vrsync::version());
        std::uint64_t cycles = 0, commands = 0;
        float heading = 45.0f * static_cast<float>(id);
        // No time limit: the host may wait for another agent that is busy (its default
        // wait_for_stop = "alive"); a dead host is still detected (throws).
        while (vrsync::Frame frame = agent.wait_start()) {
            const vrsync::Image* left = frame.find_image("left");
            const vrsync::Image* right = frame.find_image("right");
            const double l = left ? brightness(*left) : 0.0;
            const double r = right ? brightness(*right) : 0.0;
            if (frame.cycle() % 10 == 0) {
                heading += (l >= r) ? -30.0f : 30.0f;
                if (heading < 0.0f) heading += 360.0f;
                if (heading >= 360.0f) heading -= 360.0f;
                agent.send_move(heading, 0.8f);
            } else {
                agent.send_turn(l >= r ? -2.0f : 2.0f);
            }
            ++commands;
            agent.stop();  // ends the cycle; `frame`'s images are no longer valid
            ++cycles;
        }
        std::printf("cpp_agent %u: %llu cycles, %llu commands\n", id,
                    static_cast<unsigned long long>(cycles),
                    static_cast<unsigned long long>(commands));
        return 0;
    } catch (const vrsync::Error& e) {
        std::fprintf(stderr, "cpp_agent %u: error (%s): %s\n", id, e.status_name(), e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "cpp_agent %u: error: %s\n", id, e.what());
        return 1;
    }
}
