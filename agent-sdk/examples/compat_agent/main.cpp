// An agent written like the original UnityVR C++ clients, ported with
// vrsync/compat.hpp: the same loop, the same names, polling with MSLEEP(1).
//
// usage: compat_agent CONFIG AGENT_NO [MAX_TIME]
// Exit codes: 0 after MAX_TIME cycles or when the host ended the run, 1 on failure,
// 2 on bad usage.
#include <cstdio>
#include <cstdlib>

#include <vrsync/compat.hpp>

using namespace vrsync::compat;

int main(int argc, char** argv) {
    if (argc < 3 || argc > 4) {
        std::fprintf(stderr, "usage: %s CONFIG AGENT_NO [MAX_TIME]\n", argv[0]);
        return 2;
    }
    const int agentNo = std::atoi(argv[2]);
    const int maxTime = argc == 4 ? std::atoi(argv[3]) : 1000000;
    int time = 0;
    try {
        // Was: AnnarProtoMain(srv_addr, remotePort, agentNo, agentOnly) + start().
        AnnarProtoMain protoMain(argv[1], agentNo);
        protoMain.start();
        AnnarProtoReceive* receiver = protoMain.getReceiver();
        AnnarProtoSend* sender = protoMain.getSender();
        std::fprintf(stderr, "compat_agent %d: connected\n", agentNo);

        float degree = 90.0f * static_cast<float>(agentNo % 4);
        for (time = 0; time < maxTime; time++) {
            while (!receiver->hasStartSyncReceivedAndResetState()) MSLEEP(1);

            // getImages(); getOtherData();
            AnnarImage right, left;
            if (!receiver->getImageData(&right, &left)) {
                std::fprintf(stderr, "compat_agent %d: no images in cycle %d\n", agentNo, time);
                return 1;
            }
            float x = 0, y = 0, z = 0;
            receiver->getGridsensorData(x, y, z);
            int actionId = 0, state = 0;
            receiver->getActionExecState(actionId, state);

            // calculateSomethingWithData(): the brighter eye decides the turn direction.
            const bool leftBrighter = left.data()[0] >= right.data()[0];

            // sender->sendSomeMsg(); sender->sendSomeOtherMsg();
            if (time % 5 == 0) {
                degree += leftBrighter ? -20.0f : 20.0f;
                if (degree < 0.0f) degree += 360.0f;
                if (degree >= 360.0f) degree -= 360.0f;
                sender->sendAgentMovement(degree, 0.5f);
            } else {
                sender->sendAgentTurn(leftBrighter ? -3.0f : 3.0f);
            }
            sender->sendStopSync();
        }
    } catch (const SessionClosed&) {
        // The host ended the run: a clean end.
    } catch (const vrsync::Error& e) {
        std::fprintf(stderr, "compat_agent %d: error (%s): %s\n", agentNo, e.status_name(),
                     e.what());
        return 1;
    }
    std::printf("compat_agent %d: %d cycles\n", agentNo, time);
    return 0;
}
