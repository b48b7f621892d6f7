// A vrsync agent in C++ for any simulator's channels, with vrsync/agent.hpp: it reads its
// vectors ([[agent.vector]]) and sends a value for each of its actions ([[agent.action]])
// every cycle, as the Rust example channel_agent does. For example, with
//
//     [[agent.vector]]          # the host writes 7 floats into every frame
//     name = "joints"
//     len = 7
//     [[agent.action]]          # the agent answers with 7 floats in [-2, 2] ...
//     name = "torque"
//     len = 7
//     low = -2.0
//     high = 2.0
//     [[agent.action]]          # ... and a choice in 0..3
//     name = "gear"
//     n = 3
//
// each cycle reads frame.vector("joints") in place (no copy) and sends
// agent.act("torque", values) and agent.act_discrete("gear", choice). A continuous action
// swings between its bounds (shifted by the first vector's first value), a discrete one
// steps through its choices: the values depend only on the seed, the id, the cycle and
// the frame, so runs of a deterministic world repeat exactly.
//
// usage: cpp_channel_agent CONFIG AGENT_ID [SEED]
// Exit codes: 0 when the host closed the session, 1 on failure, 2 on bad usage.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include <vrsync/agent.hpp>

namespace {

std::string describe(const vrsync::ActionSpec& a) {
    std::string s(a.name());
    if (a.is_discrete()) return s + " in 0.." + std::to_string(a.n());
    s += "[" + std::to_string(a.size()) + "]";
    if (a.size() > 0) {
        s += " in [" + std::to_string(a.low()[0]) + ", " + std::to_string(a.high()[0]) + "]";
    }
    return s;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 3 || argc > 4) {
        std::fprintf(stderr, "usage: %s CONFIG AGENT_ID [SEED]\n", argv[0]);
        return 2;
    }
    const auto id = static_cast<std::uint32_t>(std::strtoul(argv[2], nullptr, 10));
    const auto seed = argc == 4 ? static_cast<std::uint32_t>(std::strtoul(argv[3], nullptr, 10))
                                : 0u;
    vrsync::init_logging();
    try {
        vrsync::Agent agent(argv[1], id);

        // The channels, as the config declares them (the host's frames carry the same).
        std::vector<vrsync::ActionSpec> actions;
        std::string summary = "vectors:";
        for (std::size_t i = 0; i < agent.vector_count(); ++i) {
            const vrsync::VectorSpec v = agent.vector_spec(i);
            summary += " " + std::string(v.name()) + "[" + std::to_string(v.size()) + "]";
        }
        summary += "; actions:";
        for (std::size_t i = 0; i < agent.action_count(); ++i) {
            actions.push_back(agent.action_spec(i));
            summary += " " + describe(actions.back());
        }
        std::fprintf(stderr, "cpp_channel_agent %u: connected; %s\n", id, summary.c_str());

        // Every value is checked before it is queued: a wrong one throws vrsync::Error
        // naming the action, and nothing is sent.
        for (const vrsync::ActionSpec& a : actions) {
            if (a.is_discrete()) continue;
            try {
                agent.act(std::string(a.name()), {0.0f});
                if (a.size() != 1) std::fprintf(stderr, "a value of the wrong length was taken\n");
            } catch (const vrsync::Error& e) {
                std::printf("cpp_channel_agent %u: refused (%s): %s\n", id, e.status_name(),
                            e.what());
            }
            break;
        }

        std::uint64_t cycles = 0, sent = 0;
        float largest = 0.0f;  // the largest |value| of any vector, over the run
        std::vector<float> value;
        while (vrsync::Frame frame = agent.wait_start()) {
            // The first value of the first vector (joint readings, a speed, ...), 0 without.
            float sensed = 0.0f;
            for (std::size_t i = 0; i < frame.vector_count(); ++i) {
                const vrsync::View<float> v = frame.vector(i);  // in place, no copy
                if (i == 0 && !v.empty() && std::isfinite(v[0])) sensed = v[0];
                for (float x : v) largest = std::max(largest, std::fabs(x));
            }
            const float phase =
                (static_cast<float>(frame.cycle()) + static_cast<float>(seed) + id * 7.0f) *
                0.05f;
            for (const vrsync::ActionSpec& a : actions) {
                const std::string name(a.name());
                if (a.is_discrete()) {
                    agent.act_discrete(name, static_cast<std::uint32_t>(
                                                 (frame.cycle() / 10 + id + seed) % a.n()));
                } else {
                    value.resize(a.size());
                    for (std::size_t i = 0; i < a.size(); ++i) {
                        const float swing = std::sin(phase + static_cast<float>(i)) -
                                            0.1f * std::tanh(sensed);
                        const float lo = a.low()[i], hi = a.high()[i];
                        value[i] = lo + (hi - lo) * (0.5f + 0.45f * std::clamp(swing, -1.0f, 1.0f));
                    }
                    agent.act(name, value);
                }
                ++sent;
            }
            agent.stop();  // the actions go with the stop; `frame`'s views end here
            ++cycles;
        }
        std::printf("cpp_channel_agent %u: %llu cycles, %llu actions, %s, largest |vector value| %g\n",
                    id, static_cast<unsigned long long>(cycles),
                    static_cast<unsigned long long>(sent), summary.c_str(),
                    static_cast<double>(largest));
        return 0;
    } catch (const vrsync::Error& e) {
        std::fprintf(stderr, "cpp_channel_agent %u: error (%s): %s\n", id, e.status_name(),
                     e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "cpp_channel_agent %u: error: %s\n", id, e.what());
        return 1;
    }
}
