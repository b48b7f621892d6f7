/* A minimal vrsync agent in C: wait for start, read the frame, send, stop.
 *
 * usage: c_agent CONFIG AGENT_ID
 * Walks a square: every 20 cycles it turns the walking heading by 90 degrees. If the config
 * gives it channels ([[agent.vector]], [[agent.action]]), it reads its vectors in place and
 * sends each action every cycle: the middle of a continuous action's bounds, choice 0 of a
 * discrete one.
 * Exit codes: 0 when the host closed the session, 1 on failure, 2 on bad usage. */
#include <stdio.h>
#include <stdlib.h>

#include <vrsync.h>

static int fail(const char *what, vrs_status_t st) {
    fprintf(stderr, "c_agent: %s: %s: %s\n", what, vrs_status_name(st), vrs_last_error_message());
    return 1;
}

/* Reads every vector of the current frame and queues a value for every action. */
static vrs_status_t channels(vrs_agent_t *agent, uint32_t vectors, uint32_t actions,
                             float *sum) {
    vrs_status_t st = VRS_OK;
    for (uint32_t i = 0; i < vectors && st == VRS_OK; ++i) {
        vrs_vector_t v;
        st = vrs_agent_vector(agent, i, &v); /* v.data points into the frame: no copy */
        for (size_t k = 0; st == VRS_OK && k < v.len; ++k) *sum += v.data[k];
    }
    for (uint32_t i = 0; i < actions && st == VRS_OK; ++i) {
        vrs_action_spec_t a;
        st = vrs_agent_action_spec(agent, i, &a);
        if (st != VRS_OK) break;
        if (a.kind == VRS_ACTION_KIND_DISCRETE) {
            st = vrs_agent_act_discrete(agent, a.name, 0);
        } else {
            float value[256]; /* the longest continuous action (MAX_ACTION_LEN) */
            const size_t n = a.len < 256 ? a.len : 256;
            for (size_t k = 0; k < n; ++k) value[k] = 0.5f * (a.low[k] + a.high[k]);
            st = vrs_agent_act(agent, a.name, value, n);
        }
    }
    return st;
}

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s CONFIG AGENT_ID\n", argv[0]);
        return 2;
    }
    const uint32_t id = (uint32_t)strtoul(argv[2], NULL, 10);
    vrs_init_logging(NULL); /* the library's log on stderr, filtered by RUST_LOG */
    vrs_agent_t *agent = NULL;
    vrs_status_t st = vrs_agent_connect(argv[1], id, -1, &agent);
    if (st != VRS_OK) return fail("connect", st);
    fprintf(stderr, "c_agent %u: connected (vrsync %s)\n", id, vrs_version());
    uint32_t vectors = 0, actions = 0;
    vrs_agent_channel_counts(agent, &vectors, &actions);

    uint64_t cycles = 0, commands = 0, sent = 0;
    float vector_sum = 0.0f;
    int code = 0;
    for (;;) {
        vrs_frame_t frame;
        /* No time limit: the host may wait for another agent that is busy (its default
           wait_for_stop = "alive"); a dead host is still detected (VRS_ERROR_HOST_GONE). */
        st = vrs_agent_wait_start(agent, -1, &frame);
        if (st == VRS_SESSION_CLOSED) break;
        if (st != VRS_OK) {
            code = fail("wait_start", st);
            break;
        }
        /* Read the left image in place: the mean of its first row. */
        vrs_image_t left;
        uint64_t sum = 0;
        if (vrs_agent_image_by_name(agent, "left", &left) == VRS_OK) {
            for (size_t i = 0; i < left.stride; ++i) sum += left.data[i];
        }
        (void)sum;
        st = channels(agent, vectors, actions, &vector_sum);
        if (st != VRS_OK) {
            code = fail("channels", st);
            break;
        }
        sent += actions;
        if (frame.cycle % 20 == 0) {
            const float heading = (float)((frame.cycle / 20) % 4) * 90.0f;
            uint32_t action = 0;
            st = vrs_agent_send_move(agent, heading, 1.0f, &action);
            if (st != VRS_OK) {
                code = fail("send_move", st);
                break;
            }
            ++commands;
        }
        st = vrs_agent_stop(agent);
        if (st == VRS_SESSION_CLOSED) break; /* the host ended the run meanwhile */
        if (st != VRS_OK) {
            code = fail("stop", st);
            break;
        }
        ++cycles;
    }
    vrs_agent_disconnect(agent);
    printf("c_agent %u: %llu cycles, %llu commands, %llu actions, vectors sum %g\n", id,
           (unsigned long long)cycles, (unsigned long long)commands, (unsigned long long)sent,
           (double)vector_sum);
    return code;
}
