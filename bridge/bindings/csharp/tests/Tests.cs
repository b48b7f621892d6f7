// Tests of the C# binding against the real libvrsync_host and real vr-agent processes
// (started by test.sh). Usage:
//   VrsyncTests.exe layout                  sizes, offsets and constants, C# side
//   VrsyncTests.exe api CONFIG              API, errors, missing agent 1 (agent 0 runs)
//   VrsyncTests.exe stop-timeout CONFIG     agent 1 stops late once: an outcome, not an exception
//   VrsyncTests.exe leave-slow CONFIG       agent 0 leaves after 3 cycles, agent 1 is slow in cycle 1
//   VrsyncTests.exe channels CONFIG SEED    vectors and actions with the Rust channel_agent example
// Prints "ok <check>" lines; exits 1 with "FAIL <why>" on the first failed check.

using System;
using System.Collections.Generic;
using System.Runtime.InteropServices;
using System.Text;
using Vrsync;

static class Tests
{
    static int Main(string[] args)
    {
        try
        {
            switch (args.Length > 0 ? args[0] : "")
            {
                case "layout": Layout(); break;
                case "api": Api(args[1]); break;
                case "stop-timeout": StopTimeout(args[1]); break;
                case "leave-slow": LeaveSlow(args[1]); break;
                case "channels": Channels(args[1], uint.Parse(args[2])); break;
                default:
                    Console.Error.WriteLine("usage: VrsyncTests.exe layout | api CONFIG | stop-timeout CONFIG | leave-slow CONFIG | channels CONFIG SEED");
                    return 2;
            }
            return 0;
        }
        catch (Exception e)
        {
            Console.Error.WriteLine("FAIL " + e);
            return 1;
        }
    }

    static void Ok(string what)
    {
        Console.Error.WriteLine("ok " + what);
    }

    static void Expect(bool condition, string what)
    {
        if (!condition)
            throw new Exception(what);
    }

    static void Equal<T>(T expected, T actual, string what)
    {
        if (!EqualityComparer<T>.Default.Equals(expected, actual))
            throw new Exception(string.Format("{0}: expected {1}, got {2}", what, expected, actual));
    }

    static VrsyncException Throws(Status status, Action action, string what)
    {
        try
        {
            action();
        }
        catch (VrsyncException e)
        {
            if (e.Status != status)
                throw new Exception(string.Format("{0}: expected {1}, got {2}: {3}", what, status, e.Status, e.Message));
            return e;
        }
        throw new Exception(what + ": no exception, expected " + status);
    }

    // ---------------------------------------------------------------------------------
    // layout: what the C# side believes; test.sh diffs it with tests/layout.c's output.

    static readonly object[] Structs =
    {
        "vrs_host_pose_t", typeof(Pose), "position=Position rotation=Rotation",
        "vrs_host_grid_position_t", typeof(GridPosition), "position=Position rotation_deg=RotationDeg",
        "vrs_host_head_motion_t", typeof(HeadMotion),
            "velocity=Velocity acceleration=Acceleration angular_velocity_deg=AngularVelocityDeg angular_acceleration_deg=AngularAccelerationDeg",
        "vrs_host_eye_position_t", typeof(EyePosition), "rotation_deg=RotationDeg rotation_velocity_deg=RotationVelocityDeg",
        "vrs_host_action_status_t", typeof(ActionStatus), "action_id=ActionId state=State",
        "vrs_host_collision_t", typeof(Collision), "action_id=ActionId collider_id=ColliderId",
        "vrs_host_sensors_t", typeof(Sensors),
            "pose=Pose reward=Reward grid=Grid head_motion=HeadMotion eye=Eye status_count=StatusCount collision_count=CollisionCount statuses=statuses collisions=collisions",
        "vrs_host_frame_t", typeof(NativeStructs.Frame), "cycle=Cycle sim_time_ns=SimTimeNs agent_id=AgentId image_count=ImageCount",
        "vrs_host_image_t", typeof(NativeStructs.Image),
            "data=Data len=Length stride=Stride width=Width height=Height format=Format camera=Camera name=Name",
        "vrs_host_camera_t", typeof(CameraInfo),
            "len=Length stride=Stride width=Width height=Height format=Format fov_horizontal_deg=FovHorizontalDeg fov_vertical_deg=FovVerticalDeg name=name",
        "vrs_host_agent_info_t", typeof(NativeStructs.AgentInfo), "agent_id=AgentId camera_count=CameraCount connected=Connected reserved=Reserved",
        "vrs_host_info_t", typeof(HostInfo),
            "cycle=Cycle sim_time_ns=SimTimeNs simulation_time_per_frame_ns=SimulationTimePerFrameNs stop_timeout_ns=StopTimeoutNs connect_timeout_ns=ConnectTimeoutNs agent_count=AgentCount sync_mode=SyncMode transport=Transport tcp_port=TcpPort max_commands_per_cycle=MaxCommandsPerCycle protocol_version=ProtocolVersion",
        "vrs_host_cycle_t", typeof(CycleResult),
            "cycle=Cycle sim_time_ns=SimTimeNs agent_count=AgentCount timed_out_agents=TimedOutAgents late_batches=LateBatches command_count=CommandCount evicted_agents=EvictedAgents rejoined_agents=RejoinedAgents left_agents=LeftAgents slow_agents=SlowAgents",
        "vrs_host_command_t", typeof(MotorCommand), "kind=Kind action_id=ActionId object_id=ObjectId reserved=reserved args=Arg0",
        "vrs_host_agent_report_t", typeof(NativeStructs.AgentReport),
            "agent_id=AgentId outcome=Outcome command_count=CommandCount reserved=Reserved commands=Commands read_cycle=ReadCycle evicted=Evicted rejoined=Rejoined left=Left slow=Slow",
        "vrs_host_stats_t", typeof(HostStats),
            "cycles=Cycles stop_timeouts=StopTimeouts agent_timeouts=AgentTimeouts late_batches=LateBatches future_batches=FutureBatches commands_received=CommandsReceived commands_overflowed=CommandsOverflowed frames_undelivered=FramesUndelivered evictions=Evictions rejoins=Rejoins frames_delivered=FramesDelivered frames_read=FramesRead statuses_dropped=StatusesDropped collisions_dropped=CollisionsDropped slow_stops=SlowStops leaves=Leaves peers_refused=PeersRefused actions_rejected=ActionsRejected resumes=Resumes",
        "vrs_host_vector_t", typeof(NativeStructs.Vector), "data=Data len=Length index=Index name=Name",
        "vrs_host_vector_spec_t", typeof(NativeStructs.VectorSpec), "low=Low high=High len=Length index=Index name=Name",
        "vrs_host_action_spec_t", typeof(NativeStructs.ActionSpec), "low=Low high=High len=Length n=N kind=Kind index=Index name=Name",
        "vrs_host_action_value_t", typeof(NativeStructs.ActionValue),
            "values=Values len=Length choice=Choice kind=Kind index=Index name=Name",
    };

    static string Snake(string pascal)
    {
        var sb = new StringBuilder();
        for (int i = 0; i < pascal.Length; i++)
        {
            if (i > 0 && char.IsUpper(pascal[i]))
                sb.Append('_');
            sb.Append(char.ToUpperInvariant(pascal[i]));
        }
        return sb.ToString();
    }

    static void Enum<T>(string prefix, Func<long, string> extra)
    {
        foreach (T v in System.Enum.GetValues(typeof(T)))
        {
            long n = Convert.ToInt64(v);
            Console.WriteLine("{0}{1}{2} {3}", prefix, extra(n), Snake(v.ToString()), n);
        }
    }

    static void Layout()
    {
        // The library's own sizes first: throws on a mismatch.
        foreach (var row in Host.CheckLayout())
            Console.Error.WriteLine(row);
        for (int i = 0; i < Structs.Length; i += 3)
        {
            string c = (string)Structs[i];
            var type = (Type)Structs[i + 1];
            Console.WriteLine("{0} sizeof {1}", c, Marshal.SizeOf(type));
            foreach (var pair in ((string)Structs[i + 2]).Split(' '))
            {
                var names = pair.Split('=');
                Console.WriteLine("{0}.{1} {2}", c, names[0], Marshal.OffsetOf(type, names[1]).ToInt64());
            }
        }
        Enum<Status>("VRS_HOST_", n => n < 0 ? "ERROR_" : "");
        Enum<PixelFormat>("VRS_HOST_PIXEL_FORMAT_", n => "");
        Enum<ActionState>("VRS_HOST_ACTION_", n => "");
        Enum<AgentOutcome>("VRS_HOST_OUTCOME_", n => "");
        Enum<CommandKind>("VRS_HOST_COMMAND_", n => "");
        Enum<Transport>("VRS_HOST_TRANSPORT_", n => "");
        Enum<ActionKind>("VRS_HOST_ACTION_KIND_", n => "");
        Console.WriteLine("VRS_HOST_MAX_STATUSES " + Sensors.MaxStatuses);
        Console.WriteLine("VRS_HOST_MAX_COLLISIONS " + Sensors.MaxCollisions);
        Console.WriteLine("VRS_HOST_MAX_IMAGES " + SensorFrame.MaxImages);
        Console.WriteLine("VRS_HOST_CAMERA_NAME_SIZE " + CameraInfo.NameSize);
        Console.WriteLine("VRS_HOST_MAX_VECTORS " + SensorFrame.MaxVectors);
        Console.WriteLine("VRS_HOST_MAX_ACTIONS " + AgentReport.MaxActions);
        Console.WriteLine("VRS_HOST_CHANNEL_NAME_SIZE " + SensorFrame.ChannelNameSize);

        // The Sensors helpers write the pairs where the C struct has them.
        Sensors s = Sensors.Create();
        for (uint i = 0; i < Sensors.MaxStatuses; i++)
            Expect(s.AddStatus(100 + i, ActionState.Walking), "AddStatus " + i);
        Expect(!s.AddStatus(999, ActionState.Finished), "17th status is dropped");
        Expect(s.AddCollision(7, 1001), "AddCollision");
        unsafe
        {
            uint* p = (uint*)&s;
            int statuses = (int)Marshal.OffsetOf(typeof(Sensors), "statuses") / 4;
            int collisions = (int)Marshal.OffsetOf(typeof(Sensors), "collisions") / 4;
            Equal(115u, p[statuses + 2 * 15], "statuses[15].action_id in memory");
            Equal((uint)ActionState.Walking, p[statuses + 2 * 15 + 1], "statuses[15].state in memory");
            Equal(1001u, p[collisions + 1], "collisions[0].collider_id in memory");
        }
        Equal(ActionState.Walking, s.GetStatus(3).State, "GetStatus");
        Equal(1001u, s.GetCollision(0).ColliderId, "GetCollision");
        Ok("layout and the Sensors helpers");
    }

    // ---------------------------------------------------------------------------------
    // api: config with agents 0 and 1; only agent 0 runs (wander).

    static void Api(string config)
    {
        var bad = Throws(Status.Config, () => new Host(config + ".missing"), "bad config path");
        Expect(bad.Message.Contains(config + ".missing"), "message names the file: " + bad.Message);
        Expect(bad.Message.Contains("VRS_HOST_ERROR_CONFIG"), "message names the status: " + bad.Message);
        Ok("a missing config is a VrsyncException carrying the native message: " + bad.Message);

        var host = new Host(config);
        var twice = Throws(Status.Create, () => new Host(config), "a second host of a live session");
        Ok("a second host of the same session is refused: " + twice.Message);
        HostInfo info = host.Info;
        Equal(2u, info.AgentCount, "agents");
        Equal(1u, info.SyncMode, "sync mode");
        Equal(Transport.Shm, info.Transport, "transport");
        Equal(0ul, info.Cycle, "first cycle");
        Equal(2, host.Agents.Length, "Agents");
        CameraInfo left = host.GetCamera(1, 0);
        Equal("left", left.Name, "camera 0 name");
        Equal(32u, left.Width, "camera width");
        Equal(PixelFormat.Rgb8, left.Format, "camera format");
        Equal("depth", host.GetCamera(1, 1).Name, "camera 1 name");
        Equal(PixelFormat.Gray8, host.GetCamera(1, 1).Format, "camera 1 format");
        Ok("info and cameras from the config");

        // Agent 0 connects (started by test.sh), agent 1 never does.
        uint[] missing = null;
        var deadline = DateTime.UtcNow.AddSeconds(20);
        while (true)
        {
            Expect(!host.TryWaitForAgents(0.2, out missing), "agent 1 cannot be connected");
            if (missing.Length == 1)
                break;
            Expect(DateTime.UtcNow < deadline, "agent 0 did not connect within 20 s");
        }
        Equal(1u, missing[0], "missing id");
        Expect(host.IsConnected(0) && !host.IsConnected(1), "IsConnected");
        try
        {
            host.WaitForAgents(0.05);
            throw new Exception("WaitForAgents did not throw");
        }
        catch (AgentsMissingException e)
        {
            Equal(1, e.Missing.Length, "AgentsMissingException.Missing");
            Equal(1u, e.Missing[0], "AgentsMissingException.Missing[0]");
            Expect(e.Message.Contains("[1]"), "message names agent 1: " + e.Message);
            Ok("agent 1 missing: " + e.Message);
        }

        // Calls out of order.
        var early = Throws(Status.WrongState, () => host.Collect(), "collect before start");
        Equal("vrs_host_collect: the cycle is before vrs_host_start; it belongs after vrs_host_start (VRS_HOST_ERROR_WRONG_STATE)",
            early.Message, "message");
        Throws(Status.WrongState, () => host.EndCycle(), "end cycle before collect");
        Throws(Status.UnknownAgent, () => host.LoanFrame(7), "unknown agent");
        Throws(Status.NoFrame, () => { var s = Sensors.Create(); host.Publish(0, ref s); }, "publish without loan");
        Ok("calls out of order are exceptions with the native message");

        for (int n = 0; n < 3; n++)
        {
            for (uint id = 0; id < 2; id++)
            {
                SensorFrame frame = host.LoanFrame(id);
                Equal((ulong)n, frame.Cycle, "frame cycle");
                Equal(2, frame.ImageCount, "image count");
                Image image = frame.GetImage("left");
                Equal(32 * 3, image.Stride, "stride");
                Equal(3, image.BytesPerPixel, "rgb8 bytes per pixel");
                Equal(image.Width * image.BytesPerPixel, image.Stride, "stride = width * bytes per pixel");
                Equal(image.Stride * image.Height, image.Pixels.Length, "span length");
                image.Pixels.Fill((byte)(10 + n));
                image.CopyFromBottomUp(new byte[image.Length], image.Stride);
                Image depth = frame.GetImage(1);
                Equal(PixelFormat.Gray8, depth.Format, "depth format");
                Equal(1, depth.BytesPerPixel, "gray8 bytes per pixel");
                depth.Row(depth.Height - 1).Fill(255);
                Throws(Status.InvalidArgument, () => frame.GetImage("nope"), "unknown camera");
                Throws(Status.OutOfRange, () => frame.GetImage(2), "image index");
                bool threw = false;
                try { Span<byte> px = image.Pixels; px[image.Length] = 1; } catch (IndexOutOfRangeException) { threw = true; }
                Expect(threw, "the span is bounded by the image");
                if (n == 0 && id == 0)
                {
                    Throws(Status.WrongState, () => host.LoanFrame(0), "second loan");
                    Throws(Status.WrongState, () => host.Start(), "start with a loaned frame");
                }
                Sensors sensors = Sensors.Create();
                sensors.Pose.Position = new Vec3(n, 0, id);
                sensors.AddStatus(1, ActionState.Finished);
                frame.Publish(ref sensors);
            }
            host.Start();
            CycleResult cycle = host.Collect();
            Equal((ulong)n, cycle.Cycle, "collected cycle");
            Equal(2u, cycle.AgentCount, "reports");
            Equal(0u, cycle.TimedOutAgents, "timeouts");
            AgentReport r0 = host.GetReport(0);
            Equal(AgentOutcome.Stopped, r0.Outcome, "agent 0 outcome");
            Equal((int)cycle.CommandCount, r0.Commands.Length, "agent 0 commands");
            for (int i = 0; i < r0.Commands.Length; i++)
            {
                MotorCommand copy = host.GetCommand(0, i);
                Equal(r0.Commands[i].ActionId, copy.ActionId, "command copy");
                Expect(copy.IsWellFormed, "wander sends well-formed commands: " + copy);
            }
            Equal((long)n, r0.ReadCycle, "agent 0 acknowledged the frame it answered");
            Expect(!r0.Evicted && !r0.Rejoined, "agent 0 neither evicted nor rejoined");
            Expect(!r0.Left && !r0.Slow, "agent 0 neither left nor slow");
            AgentReport r1 = host.GetReport(1);
            Equal(1u, r1.AgentId, "agent 1 id");
            Equal(AgentOutcome.NotAwaited, r1.Outcome, "agent 1 (not connected) is not awaited");
            Equal(0, r1.Commands.Length, "agent 1 commands");
            Equal(-1L, r1.ReadCycle, "agent 1 read nothing");
            Throws(Status.OutOfRange, () => host.GetReport(2), "report index");
            AgentReport byId = host.GetReportById(0);
            Equal(0u, byId.AgentId, "report by id");
            Equal(r0.Commands.Length, byId.Commands.Length, "report by id: commands");
            AgentSummary summary = host.GetSummary(0);
            Func<AgentSummary> captured = () => summary; // a summary may be captured
            Equal(r0.Commands.Length, captured().CommandCount, "summary command count");
            Expect(!captured().Left && !captured().Slow, "summary: neither left nor slow");
            Equal(AgentOutcome.Stopped, captured().Outcome, "summary outcome");
            Throws(Status.UnknownAgent, () => host.GetReportById(9), "report of an unknown id");
            Equal(0u, cycle.EvictedAgents + cycle.RejoinedAgents, "no evictions or rejoins");
            Equal(0u, cycle.LeftAgents + cycle.SlowAgents, "no leaves or slow agents");
            Throws(Status.WrongState, () => host.LoanFrame(0), "loan before end cycle");
            host.SetRejected(0, 0);
            host.EndCycle();
        }
        Equal(3ul, host.Info.Cycle, "cycle after 3");
        HostInfo seconds = host.Info;
        Expect(seconds.SimulationTimePerFrame > 0 && seconds.SimulationTimePerFrame == seconds.SimulationTimePerFrameNs / 1e9,
            "SimulationTimePerFrame in seconds");
        Expect(seconds.SimTime == seconds.SimTimeNs / 1e9, "SimTime in seconds");
        Expect(seconds.StopTimeout == seconds.StopTimeoutNs / 1e9 && seconds.ConnectTimeout == seconds.ConnectTimeoutNs / 1e9,
            "timeouts in seconds");
        HostStats stats = host.Stats;
        Equal(3ul, stats.Cycles, "stats cycles");
        Equal(0ul, stats.StopTimeouts, "stats stop timeouts");
        Equal(3ul, stats.FramesUndelivered, "frames for agent 1 undelivered");
        Equal(3ul, stats.FramesDelivered, "frames for agent 0 delivered");
        Equal(3ul, stats.FramesRead, "frames agent 0 acknowledged");
        Equal(0ul, stats.Evictions + stats.Rejoins, "no evictions or rejoins");
        Equal(0ul, stats.SlowStops, "stats slow stops");
        Equal(0ul, stats.Leaves, "stats leaves");
        Equal(0ul, stats.PeersRefused, "stats peers refused");
        Ok("3 cycles: agent 0 stopped, agent 1 not awaited; images through spans");

        // Discard: the agent is not waited for.
        host.LoanFrame(0).Discard();
        Throws(Status.NoFrame, () => host.DiscardFrame(0), "double discard");
        host.Start();
        Equal(AgentOutcome.NotAwaited, (host.Collect().AgentCount == 2 ? host.GetReport(0).Outcome : AgentOutcome.Other), "discarded");
        host.EndCycle();
        Ok("a discarded frame is not waited for");

        host.Dispose();
        host.Dispose();
        bool disposed = false;
        try { var i = host.Info; } catch (ObjectDisposedException) { disposed = true; }
        Expect(disposed, "use after Dispose is ObjectDisposedException");
        Ok("Dispose is idempotent; use after Dispose throws ObjectDisposedException");

        // A host left to the garbage collector (Unity: a domain reload without Dispose):
        // the finalizer thread's destroy is deferred to this thread's next call, so the
        // session can be created again here (while the old host lived, that was refused).
        Abandon(config);
        GC.Collect();
        GC.WaitForPendingFinalizers();
        using (var again = new Host(config))
            Equal(0ul, again.Info.Cycle, "a fresh host");
        Ok("a finalized host is destroyed on its own thread; the session is reusable");

        Throws(Status.InvalidArgument, () => Host.InitLogging("[[["), "bad log filter");
        Ok("api");
    }

    [System.Runtime.CompilerServices.MethodImpl(System.Runtime.CompilerServices.MethodImplOptions.NoInlining)]
    static void Abandon(string config)
    {
        var h = new Host(config);
        Equal(0ul, h.Info.Cycle, "abandoned host");
    }

    // ---------------------------------------------------------------------------------
    // stop-timeout: agents 0 and 1 run; agent 1 stops late (twice stop_timeout) in cycle 2.

    static void StopTimeout(string config)
    {
        using (var host = new Host(config))
        {
            host.WaitForAgents(20);
            double timeoutS = host.Info.StopTimeout;
            var outcomes = new List<AgentOutcome[]>();
            var timedOut = new List<uint>();
            const int cycles = 8;
            for (int n = 0; n < cycles; n++)
            {
                for (uint id = 0; id < 2; id++)
                {
                    SensorFrame frame = host.LoanFrame(id);
                    for (int i = 0; i < frame.ImageCount; i++)
                        frame.GetImage(i).Pixels.Fill(128);
                    Sensors sensors = Sensors.Create();
                    frame.Publish(ref sensors);
                }
                host.Start();
                var started = DateTime.UtcNow;
                CycleResult cycle = host.Collect(); // must not throw
                double waited = (DateTime.UtcNow - started).TotalSeconds;
                var row = new AgentOutcome[2];
                for (int i = 0; i < cycle.AgentCount; i++)
                {
                    AgentReport r = host.GetReport(i);
                    row[r.AgentId] = r.Outcome;
                }
                outcomes.Add(row);
                timedOut.Add(cycle.TimedOutAgents);
                Console.Error.WriteLine(string.Format("cycle {0}: agent 0 {1}, agent 1 {2}, waited {3:0.000} s",
                    cycle.Cycle, row[0], row[1], waited));
                if (row[1] == AgentOutcome.TimedOut)
                    Expect(waited >= timeoutS * 0.9, "a timed-out cycle waited the stop timeout");
                host.EndCycle();
            }
            Equal(AgentOutcome.TimedOut, outcomes[2][1], "agent 1 in cycle 2");
            Equal(1u, timedOut[2], "timed-out agents in cycle 2");
            for (int n = 0; n < cycles; n++)
                Equal(AgentOutcome.Stopped, outcomes[n][0], "agent 0 in cycle " + n);
            Equal(AgentOutcome.Stopped, outcomes[cycles - 1][1], "agent 1 caught up by the last cycle");
            HostStats stats = host.Stats;
            Expect(stats.StopTimeouts >= 1, "stop timeouts counted");
            Expect(stats.LateBatches >= 1, "the late stop was dropped as late");
            Console.Error.WriteLine(string.Format("stop_timeouts={0} agent_timeouts={1} late_batches={2}",
                stats.StopTimeouts, stats.AgentTimeouts, stats.LateBatches));
        }
        Ok("stop-timeout: a late agent is an outcome in its report, not an exception");
    }

    // ---------------------------------------------------------------------------------
    // leave-slow: wait_for_stop = "alive"; agent 0 (vr-agent --frames 3) stops cycles 0..2
    // and leaves; agent 1 (--late-stop-at 1) computes 1.5 stop timeouts in cycle 1.

    static void LeaveSlow(string config)
    {
        using (var host = new Host(config))
        {
            host.WaitForAgents(20);
            const int cycles = 6;
            int leftIn = -1;
            for (int n = 0; n < cycles; n++)
            {
                for (uint id = 0; id < 2; id++)
                {
                    SensorFrame frame = host.LoanFrame(id);
                    for (int i = 0; i < frame.ImageCount; i++)
                        frame.GetImage(i).Pixels.Fill(128);
                    Sensors sensors = Sensors.Create();
                    frame.Publish(ref sensors);
                }
                host.Start();
                CycleResult cycle = host.Collect();
                AgentReport r0 = host.GetReportById(0);
                AgentReport r1 = host.GetReportById(1);
                Console.Error.WriteLine(string.Format("cycle {0}: {1}; {2}; left {3}, slow {4}",
                    cycle.Cycle, r0.Summary, r1.Summary, cycle.LeftAgents, cycle.SlowAgents));
                Equal(0u, cycle.TimedOutAgents, "timed-out agents in cycle " + n);
                Equal(0u, cycle.EvictedAgents, "evicted agents in cycle " + n);
                // The leave comes after the stop of cycle 2: with it, or in cycle 3.
                if (r0.Left)
                {
                    Equal(-1, leftIn, "agent 0 leaves once");
                    leftIn = n;
                    Expect(r0.Summary.Left, "the summary carries Left");
                    // With its stop of cycle 2: Stopped. In cycle 3: Left when the leave came
                    // during the wait, NotAwaited when it came before the cycle's frames (the
                    // host let it go at once).
                    if (n == 2)
                        Equal(AgentOutcome.Stopped, r0.Outcome, "agent 0 outcome as it leaves with its stop");
                    else
                        Expect(r0.Outcome == AgentOutcome.Left || r0.Outcome == AgentOutcome.NotAwaited,
                            "agent 0 outcome as it leaves in cycle 3: Left or NotAwaited, not " + r0.Outcome);
                }
                Equal(r0.Left ? 1u : 0u, cycle.LeftAgents, "left agents in cycle " + n);
                Equal(n == 1, r1.Slow, "agent 1 slow in cycle " + n);
                Equal(n == 1 ? 1u : 0u, cycle.SlowAgents, "slow agents in cycle " + n);
                Expect(!r0.Slow && !r1.Left, "agent 0 never slow, agent 1 never leaves");
                Equal(AgentOutcome.Stopped, r1.Outcome, "agent 1 in cycle " + n);
                if (n > 3)
                    Equal(AgentOutcome.NotAwaited, r0.Outcome, "agent 0 is gone in cycle " + n);
                host.EndCycle();
            }
            Expect(leftIn == 2 || leftIn == 3, "agent 0 left in cycle 2 or 3, not " + leftIn);
            Expect(!host.IsConnected(0), "agent 0 is not connected after its leave");
            HostStats stats = host.Stats;
            Console.Error.WriteLine(string.Format("leaves={0} slow_stops={1} stop_timeouts={2} evictions={3} peers_refused={4}",
                stats.Leaves, stats.SlowStops, stats.StopTimeouts, stats.Evictions, stats.PeersRefused));
            Equal(1ul, stats.Leaves, "stats leaves");
            Equal(1ul, stats.SlowStops, "stats slow stops");
            Equal(0ul, stats.StopTimeouts + stats.AgentTimeouts, "stats timeouts");
            Equal(0ul, stats.Evictions, "stats evictions");
            Equal(0ul, stats.PeersRefused, "stats peers refused");
        }
        Ok("leave-slow: a graceful leave and a slow agent in the reports and the stats");
    }

    // ---------------------------------------------------------------------------------
    // channels: agent 0 with vectors joints[3] (bounds -1..1), vel[2] and actions
    // torque[3] (bounds -2..2), gear (n = 3), run by the Rust example channel_agent with
    // SEED: its torque depends on the seed, the cycle and the first value of its first
    // vector, so the values the host reads prove that the vector arrived too.

    static float ExpectedTorque(ulong cycle, uint seed, float sensed, int i, float lo, float hi)
    {
        float phase = ((float)cycle + (float)seed) * 0.05f;
        float swing = (float)Math.Sin(phase + i) - 0.1f * (float)Math.Tanh(sensed);
        swing = Math.Max(-1f, Math.Min(1f, swing));
        return lo + (hi - lo) * (0.5f + 0.45f * swing);
    }

    static void Channels(string config, uint seed)
    {
        using (var host = new Host(config))
        {
            AgentInfo agent = host.Agents[0];
            Equal(2, agent.Vectors.Length, "vectors");
            Equal("joints", agent.Vectors[0].Name, "vector 0");
            Equal(3, agent.Vectors[0].Length, "joints length");
            Equal(-1f, agent.Vectors[0].Low[2], "joints low");
            Equal("vel", agent.Vectors[1].Name, "vector 1");
            Expect(float.IsPositiveInfinity(agent.Vectors[1].High[1]), "vel: no bound is +inf");
            Equal(2, agent.Actions.Length, "actions");
            ActionSpec torqueSpec = agent.Actions[0];
            Equal("torque", torqueSpec.Name, "action 0");
            Equal(ActionKind.Box, torqueSpec.Kind, "torque kind");
            Equal(3, torqueSpec.Length, "torque length");
            Equal(2f, torqueSpec.High[0], "torque high");
            Equal(ActionKind.Discrete, agent.Actions[1].Kind, "gear kind");
            Equal(3u, agent.Actions[1].N, "gear choices");
            Equal(0, agent.Actions[1].Low.Length, "a discrete action has no bounds");
            Ok("channel specs from the config");

            host.WaitForAgents(20);
            Throws(Status.NoFrame, () => host.GetVector(0, "joints"), "a vector without a loaned frame");
            const int cycles = 12;
            for (int n = 0; n < cycles; n++)
            {
                SensorFrame frame = host.LoanFrame(0);
                for (int i = 0; i < frame.ImageCount; i++)
                    frame.GetImage(i).Pixels.Fill(64);
                Span<float> joints = frame.Vector("joints");
                Equal(3, joints.Length, "joints span");
                float sensed = 0.25f * n - 1f;
                joints[0] = sensed;
                joints[1] = 0f;
                joints[2] = -sensed;
                Span<float> vel = frame.Vector(1);
                Equal(2, vel.Length, "vel span");
                vel.Fill(n);
                var unknown = Throws(Status.UnknownChannel, () => frame.Vector("speed"), "an unknown vector");
                Expect(unknown.Message.Contains("\"speed\"") && unknown.Message.Contains("joints, vel"),
                    "the message names the vector and the agent's vectors: " + unknown.Message);
                Throws(Status.OutOfRange, () => frame.Vector(2), "vector index");
                bool threw = false;
                try { Span<float> j = frame.Vector(0); j[3] = 1f; } catch (IndexOutOfRangeException) { threw = true; }
                Expect(threw, "the span is bounded by the vector");
                Sensors sensors = Sensors.Create();
                frame.Publish(ref sensors);
                host.Start();
                Throws(Status.WrongState, () => host.GetAction(0, "torque"), "an action before collect");
                CycleResult cycle = host.Collect();
                Equal(0u, cycle.TimedOutAgents, "timeouts");
                AgentReport r = host.GetReportById(0);
                Equal(AgentOutcome.Stopped, r.Outcome, "outcome");
                Equal(0, r.Commands.Length, "actions are not commands");
                ActionValue torque = r.Action("torque");
                Equal(ActionKind.Box, torque.Kind, "torque sent");
                Equal(3, torque.Values.Length, "torque values");
                for (int i = 0; i < 3; i++)
                {
                    float want = ExpectedTorque(cycle.Cycle, seed, sensed, i, torqueSpec.Low[i], torqueSpec.High[i]);
                    Expect(Math.Abs(torque.Values[i] - want) < 1e-4,
                        string.Format("cycle {0} torque[{1}] = {2}, expected {3} (from joints[0] = {4})",
                            cycle.Cycle, i, torque.Values[i], want, sensed));
                }
                float[] kept = torque.ToArray();
                Equal(torque.Values[2], kept[2], "ToArray");
                ActionValue gear = r.Action(1);
                Equal(ActionKind.Discrete, gear.Kind, "gear sent");
                Equal((uint)((cycle.Cycle / 10 + seed) % 3), gear.Choice, "gear choice");
                Equal(0, gear.Values.Length, "a choice has no values");
                var thrust = Throws(Status.UnknownChannel, () => host.GetAction(0, "thrust"), "an unknown action");
                Expect(thrust.Message.Contains("\"thrust\"") && thrust.Message.Contains("torque, gear"),
                    "the message names the action and the agent's actions: " + thrust.Message);
                Throws(Status.OutOfRange, () => host.GetAction(0, 2), "action index");
                Throws(Status.UnknownAgent, () => host.GetAction(4, 0), "an unknown agent");
                Equal(0u, r.ActionsRejected, "actions rejected");
                host.EndCycle();
            }
            Throws(Status.WrongState, () => host.GetAction(0, 0), "an action after the cycle ended");
            HostStats stats = host.Stats;
            Equal((ulong)cycles, stats.Cycles, "cycles");
            Equal(0ul, stats.ActionsRejected, "stats actions rejected");
            Equal(0ul, stats.StopTimeouts, "stop timeouts");
        }
        Ok("channels: vectors written in place reach the agent, its actions reach the report");
    }
}
