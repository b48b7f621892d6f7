// A scene played through the Unity API stubs (../UnityStubs) with the package's components,
// against real agent processes (bridge/bindings/unity/test.sh starts them):
//   one VrsyncHost; agents 0 and 1 (VrsyncAgent + TestBody), each with two VrsyncCameras
//   whose "renders" draw a known pattern that depends on the cycle, the agent and the camera.
// It runs --cycles sync cycles and prints key=value lines; exit 0 when every check passed:
//   - Time.captureDeltaTime == simulation_time_per_frame and every frame advanced by it;
//   - every published image holds the pattern of its cycle, agent and camera, top row first
//     (checked here in the loaned memory; the Python agent checks what it receives);
//   - every command reaches the agent's IVrsyncBody (--exact-commands ID: exactly one per
//     cycle from that agent, as tests~/SceneTest/pattern_agent.py sends) and the Python
//     agent's channel action values arrive (--actions-from ID);
//   - 0 stop timeouts; every readback completed and every safety handle released.
// Usage: mono SceneTest.exe --config FILE --cycles N [--exact-commands ID] [--actions-from ID]
//        [--readpixels AGENT:CAMERA]... [--refuse TEXTUREFORMAT] [--async] [--deadline SECONDS]
// --async: the config has sync_mode = false; then captureDeltaTime must stay unset, the
// frames are published when their readbacks finished (not waited for), and the commands and
// actions are only counted (an async agent's values belong to no particular cycle).

using System;
using System.Collections.Generic;
using System.IO;
using Unity.Collections.LowLevel.Unsafe;
using UnityEngine;
using UnityEngine.Rendering;
using Vrsync;

namespace Vrsync.SceneTest
{
    /// <summary>The test pattern: byte <paramref name="c"/> of pixel (x, y), y counted from
    /// the TOP row. pattern_agent.py computes the same.</summary>
    static class Pattern
    {
        public static byte At(ulong cycle, uint agent, int camera, int x, int y, int c)
        {
            return (byte)((x * 7 + y * 13 + c * 50 + (int)(cycle % 256) * 3 + (int)agent * 41 + camera * 17) & 0xFF);
        }

        /// <summary>Torque the Python agent sends in <paramref name="cycle"/>.</summary>
        public static float[] Torque(ulong cycle)
        {
            return new[] { (cycle % 10) / 10.0f, -0.5f };
        }

        /// <summary>The "joints" vector the body writes in <paramref name="cycle"/>.</summary>
        public static float[] Joints(ulong cycle, uint agent)
        {
            return new[] { (float)(cycle % 1000), agent, 0.25f };
        }
    }

    /// <summary>An IVrsyncBody that records what reaches it and checks the frames.</summary>
    public sealed class TestBody : MonoBehaviour, IVrsyncBody
    {
        public VrsyncHost Host;
        public bool CheckActionValues = true;
        public int Commands;
        public int Actions;
        public int ActionErrors;
        public int ImagesChecked;
        public int ImageErrors;
        public readonly List<string> Errors = new List<string>();

        public bool Apply(VrsyncAgent agent, MotorCommand command)
        {
            Commands++;
            // Report it finished at once, so wander-like agents keep sending.
            agent.ReportStatus(command.ActionId, ActionState.Finished);
            return command.IsWellFormed;
        }

        public void ApplyActions(VrsyncAgent agent, AgentReport report)
        {
            if (agent.Info.Actions.Length == 0)
                return;
            ActionValue torque = report.Action("torque");
            if (!torque.HasValue)
                return;
            Actions++;
            if (!CheckActionValues)
                return;
            float[] want = Pattern.Torque(Host.Cycle);  // the cycle being collected
            float[] got = torque.ToArray();
            if (got.Length != want.Length || got[0] != want[0] || got[1] != want[1])
            {
                ActionErrors++;
                Note(string.Format("agent {0} cycle {1}: torque [{2}], expected [{3}]", agent.agentId,
                    Host.Cycle, string.Join(", ", got), string.Join(", ", want)));
            }
        }

        public void WriteSensors(VrsyncAgent agent, SensorFrame frame, ref Sensors sensors)
        {
            if (agent.Info.Vectors.Length > 0)
            {
                Span<float> joints = frame.Vector("joints");
                float[] value = Pattern.Joints(frame.Cycle, agent.agentId);
                for (int i = 0; i < joints.Length; i++)
                    joints[i] = value[i];
            }
            // The images are complete here: compare the loaned memory with the pattern.
            for (int cam = 0; cam < frame.ImageCount; cam++)
            {
                Image image = frame.GetImage(cam);
                Span<byte> pixels = image.Pixels;
                int bpp = image.BytesPerPixel, bad = 0;
                for (int y = 0; y < image.Height; y++)
                    for (int x = 0; x < image.Width; x++)
                        for (int c = 0; c < bpp; c++)
                            if (pixels[y * image.Stride + x * bpp + c] != Pattern.At(frame.Cycle, agent.agentId, cam, x, y, c))
                                bad++;
                ImagesChecked++;
                if (bad > 0)
                {
                    ImageErrors++;
                    Note(string.Format("agent {0} camera {1} cycle {2}: {3} bytes differ from the pattern",
                        agent.agentId, cam, frame.Cycle, bad));
                }
            }
        }

        void Note(string error)
        {
            if (Errors.Count < 10)
                Errors.Add(error);
        }
    }

    static class Program
    {
        static int Main(string[] args)
        {
            try
            {
                return Run(args);
            }
            catch (Exception e)
            {
                Console.Error.WriteLine("SceneTest: " + e);
                return 1;
            }
        }

        static int Run(string[] args)
        {
            string config = null;
            int cycles = 100;
            double deadlineSeconds = 120;
            int exactCommands = -1, actionsFrom = -1;
            bool async = false;
            var readPixels = new HashSet<string>();
            for (int i = 0; i < args.Length; i++)
            {
                switch (args[i])
                {
                    case "--config": config = args[++i]; break;
                    case "--cycles": cycles = int.Parse(args[++i]); break;
                    case "--deadline": deadlineSeconds = double.Parse(args[++i]); break;
                    case "--exact-commands": exactCommands = int.Parse(args[++i]); break;
                    case "--actions-from": actionsFrom = int.Parse(args[++i]); break;
                    case "--readpixels": readPixels.Add(args[++i]); break;
                    case "--async": async = true; break;
                    case "--refuse":  // a readback format this "platform" cannot convert to
                        AsyncGPUReadback.StubUnsupported.Add((TextureFormat)Enum.Parse(typeof(TextureFormat), args[++i]));
                        break;
                    default:
                        Console.Error.WriteLine("SceneTest: unknown argument " + args[i]);
                        return 2;
                }
            }
            if (config == null)
            {
                Console.Error.WriteLine("usage: SceneTest.exe --config FILE --cycles N ...");
                return 2;
            }

            // The scene: the config in StreamingAssets, as a player would have it.
            Application.streamingAssetsPath = Path.GetDirectoryName(Path.GetFullPath(config));
            var player = new StubPlayer();
            var hostObject = new GameObject("vrsync");
            VrsyncHost host = hostObject.AddComponent<VrsyncHost>();
            host.configPath = Path.GetFileName(config);
            host.agentWaitSeconds = 30;
            player.Add(hostObject);

            string[][] cameraNames = { new[] { "left", "right" }, new[] { "left", "gray" } };
            var bodies = new TestBody[2];
            var agents = new VrsyncAgent[2];
            for (uint id = 0; id < 2; id++)
            {
                var body = new GameObject("agent" + id);
                body.transform.position = new Vector3(id, 0, 2 * id);
                bodies[id] = body.AddComponent<TestBody>();
                bodies[id].Host = host;
                bodies[id].CheckActionValues = !async;
                agents[id] = body.AddComponent<VrsyncAgent>();
                agents[id].agentId = id;
                for (int c = 0; c < 2; c++)
                {
                    var eye = new GameObject("agent" + id + "-" + cameraNames[id][c]);
                    eye.transform.SetParent(body.transform);
                    eye.AddComponent<Camera>();
                    VrsyncCamera vc = eye.AddComponent<VrsyncCamera>();
                    vc.cameraName = cameraNames[id][c];
                    if (readPixels.Contains(id + ":" + vc.cameraName))
                        vc.readback = ReadbackMode.ReadPixels;
                }
                player.Add(body);
            }

            // The "renderer": each camera draws the pattern of the cycle being loaned into its
            // RenderTexture, in Unity's row order (row 0 of the texture = the image's bottom row).
            Camera.StubRenderer = camera =>
            {
                VrsyncCamera vc = camera.GetComponent<VrsyncCamera>();
                VrsyncAgent agent = camera.transform.parent.gameObject.GetComponent<VrsyncAgent>();
                int index = Array.IndexOf(cameraNames[agent.agentId], vc.cameraName);
                RenderTexture rt = camera.targetTexture;
                int w = rt.width, h = rt.height, bpp = rt.StubBytesPerPixel;
                int channels = vc.Info.Format == PixelFormat.Gray8 ? 1 : 4;
                for (int row = 0; row < h; row++)
                    for (int x = 0; x < w; x++)
                        for (int c = 0; c < channels; c++)
                            rt.StubPixels[(row * w + x) * bpp + c] = Pattern.At(host.Cycle, agent.agentId, index, x, h - 1 - row, c);
            };

            var frameTimes = new List<float>();
            int frames = 0;
            var deadline = DateTime.UtcNow.AddSeconds(deadlineSeconds);
            player.Play();
            while (host.CyclesCompleted < cycles)
            {
                if (host.Phase == VrsyncHostPhase.Failed || host.Phase == VrsyncHostPhase.Closed)
                    throw new Exception("the host ended: " + host.Phase + " " + host.Error);
                if (DateTime.UtcNow > deadline)
                    throw new TimeoutException(string.Format(
                        "{0} of {1} cycles after {2} s (phase {3})", host.CyclesCompleted, cycles, deadlineSeconds, host.Phase));
                // A frame's deltaTime is fixed when it begins: the frame in which the host
                // opened (its Start sets Time.captureDeltaTime, for the frames after it) may
                // also be the one in which every agent connected, so only the frames that
                // began with the session running count.
                bool running = host.Phase == VrsyncHostPhase.Running;
                player.Frame();
                frames++;
                if (running)
                    frameTimes.Add(Time.deltaTime);
            }
            float captureDeltaTime = Time.captureDeltaTime;
            double perFrame = host.SimulationTimePerFrame;
            HostStats stats = host.Host.Stats;
            HostInfo info = host.Host.Info;
            int readbacksRequested = AsyncGPUReadback.StubRequested;
            int readbacksCompleted = AsyncGPUReadback.StubCompleted;
            int readbacksRefused = AsyncGPUReadback.StubRefused;
            player.Stop();  // OnDisable/OnDestroy: the session closes, the agents exit 0

            var failures = new List<string>();
            Action<bool, string> check = (ok, what) => { if (!ok) failures.Add(what); };
            check(host.Phase == VrsyncHostPhase.Closed, "host phase after Stop: " + host.Phase);
            check(host.SyncMode == !async, "the config's sync_mode is " + host.SyncMode);
            if (!async)
            {
                check(captureDeltaTime == (float)perFrame,
                    string.Format("Time.captureDeltaTime {0}, simulation_time_per_frame {1}", captureDeltaTime, perFrame));
                check(frameTimes.TrueForAll(dt => dt == (float)perFrame), "a running frame's deltaTime was not simulation_time_per_frame");
            }
            else
            {
                check(captureDeltaTime == 0, "async mode set Time.captureDeltaTime to " + captureDeltaTime);
            }
            check(Time.captureDeltaTime == 0, "Time.captureDeltaTime not restored after the session closed: " + Time.captureDeltaTime);
            check(stats.StopTimeouts == 0, "stop_timeouts " + stats.StopTimeouts);
            check(stats.AgentTimeouts == 0, "agent_timeouts " + stats.AgentTimeouts);
            check(stats.Evictions == 0 && stats.Leaves == 0, string.Format("evictions {0}, leaves {1}", stats.Evictions, stats.Leaves));
            if (!async)
                check(Math.Abs(info.SimTime - cycles * perFrame) < 1e-6,
                    string.Format("sim time {0} s after {1} cycles of {2} s", info.SimTime, cycles, perFrame));
            check(readbacksRequested == readbacksCompleted + readbacksRefused,
                string.Format("readbacks requested {0}, completed {1}, refused {2}", readbacksRequested, readbacksCompleted, readbacksRefused));
            check(AtomicSafetyHandle.StubLive == 0, "safety handles not released: " + AtomicSafetyHandle.StubLive);
            int expectedReadbacks = 0;
            foreach (VrsyncAgent a in agents)
                foreach (VrsyncCamera c in a.Cameras)
                {
                    if (!c.UsesReadPixels)
                        expectedReadbacks += cycles + 1;  // cycle `cycles` was published, not collected
                    else if (c.readback != ReadbackMode.ReadPixels)
                        expectedReadbacks += 1;  // refused once, then ReadPixels
                }
            // Async: a capture may be in flight when the scene stops (waited for, not published).
            if (!async)
                check(readbacksRequested == expectedReadbacks,
                string.Format("readbacks requested {0}, expected {1}", readbacksRequested, expectedReadbacks));

            Console.WriteLine("cycles=" + host.CyclesCompleted);
            Console.WriteLine("frames=" + frames);
            Console.WriteLine("capture_delta_time=" + captureDeltaTime);
            Console.WriteLine("sim_time_s=" + info.SimTime);
            Console.WriteLine("stop_timeouts=" + stats.StopTimeouts);
            Console.WriteLine("agent_timeouts=" + stats.AgentTimeouts);
            Console.WriteLine("readbacks=" + readbacksCompleted);
            Console.WriteLine("readbacks_refused=" + readbacksRefused);
            for (uint id = 0; id < 2; id++)
            {
                TestBody b = bodies[id];
                Console.WriteLine(string.Format("agent{0}_commands={1}", id, b.Commands));
                Console.WriteLine(string.Format("agent{0}_applied={1}", id, agents[id].CommandsApplied));
                Console.WriteLine(string.Format("agent{0}_actions={1}", id, b.Actions));
                Console.WriteLine(string.Format("agent{0}_images_checked={1}", id, b.ImagesChecked));
                Console.WriteLine(string.Format("agent{0}_image_errors={1}", id, b.ImageErrors));
                foreach (VrsyncCamera c in agents[id].Cameras)
                    Console.WriteLine(string.Format("agent{0}_{1}_path={2}", id, c.cameraName,
                        c.UsesReadPixels ? "ReadPixels" : "AsyncGPUReadback"));
                foreach (string e in b.Errors)
                    failures.Add(e);
                check(b.ImageErrors == 0, "agent " + id + ": images differ from the pattern");
                check(async ? b.ImagesChecked >= 2 * cycles : b.ImagesChecked == 2 * (cycles + 1),
                    string.Format("agent {0}: {1} images checked", id, b.ImagesChecked));
                check(b.Commands > 0, "agent " + id + ": no command reached its body");
                check(b.Commands == agents[id].CommandsApplied + agents[id].CommandsRejected, "agent " + id + ": commands counted twice");
                if (exactCommands == (int)id && !async)
                    check(b.Commands == cycles, string.Format("agent {0}: {1} commands, expected {2}", id, b.Commands, cycles));
                if (actionsFrom == (int)id && async)
                    check(b.Actions > 0, string.Format("agent {0}: no action arrived", id));
                if (actionsFrom == (int)id && !async)
                    check(b.Actions == cycles && b.ActionErrors == 0,
                        string.Format("agent {0}: {1} actions ({2} wrong), expected {3}", id, b.Actions, b.ActionErrors, cycles));
            }
            foreach (string f in failures)
                Console.Error.WriteLine("SceneTest: FAIL: " + f);
            return failures.Count == 0 ? 0 : 1;
        }
    }
}
