// A console vrsync host in C#, no Unity needed: a small room with walking bodies, driven
// by the Unity-shaped SyncDriver. Run it against vr-agent processes:
//
//   mono VrsyncConsoleHost.exe --config config/default.toml --cycles 100
//   vr-agent --config config/default.toml --id 0 --policy wander   (and --id 1)
//
// It prints a summary (key=value lines) and exits 0, or prints the error and exits 1
// (2 for bad usage).

using System;
using System.Collections.Generic;
using System.Diagnostics;

namespace Vrsync.Examples
{
    /// <summary>
    /// One body in a 10 m x 10 m room: walks at 3 m/s, turns at 180 deg/s (the defaults of
    /// vr-sim's world), reports statuses and wall collisions like the original.
    /// </summary>
    public sealed class KinematicBody : IAgentBody
    {
        public const float HalfRoom = 5f;
        public const float Radius = 0.3f;
        public const float Speed = 3f;
        public const float TurnSpeedDeg = 180f;
        /// <summary>Collider ids of the walls: north (+z), east, south, west.</summary>
        public const uint WallCollider = 1000;

        enum Motion { None, Move, Turn }

        readonly uint id;
        readonly Vec3 start;
        readonly float startHeading;
        Vec3 position;
        float headingDeg;
        Vec3 velocity;
        Vec3 eye;
        Motion motion;
        uint actionId;
        float remaining;      // metres (move) or degrees (turn)
        float moveHeadingDeg;
        Sensors events = Sensors.Create();  // statuses and collisions since the last frame

        public KinematicBody(uint id, Vec3 start, float headingDeg)
        {
            this.id = id;
            this.start = start;
            startHeading = headingDeg;
            Reset();
        }

        public uint AgentId
        {
            get { return id; }
        }

        public Vec3 Position
        {
            get { return position; }
        }

        public float HeadingDeg
        {
            get { return headingDeg; }
        }

        /// <summary>Metres walked so far.</summary>
        public float Walked { get; private set; }

        public long Collisions { get; private set; }

        void Reset()
        {
            position = start;
            headingDeg = startHeading;
            velocity = new Vec3(0, 0, 0);
            motion = Motion.None;
        }

        /// <summary>A stand-in renderer: sky above the horizon, a floor whose shade follows
        /// the heading, a wall band whose brightness follows the distance ahead. Written
        /// straight into the shared-memory image, row by row.</summary>
        public void Render(SensorFrame frame)
        {
            byte shade = (byte)(40 + (int)(headingDeg / 360f * 160f));
            byte wall = (byte)Math.Max(0, 220 - (int)(DistanceAhead() * 20f));
            for (int i = 0; i < frame.ImageCount; i++)
            {
                Image image = frame.GetImage(i);
                int bpp = image.Width == 0 ? 1 : image.Stride / image.Width;
                Span<byte> pixels = image.Pixels;
                int horizon = image.Height / 2;
                int wallTop = horizon - image.Height / 6;
                for (int y = 0; y < image.Height; y++)
                {
                    Span<byte> row = pixels.Slice(y * image.Stride, image.Stride);
                    if (y != 0 && y != wallTop && y != horizon)
                    {
                        // Same band as the row above: copy it.
                        pixels.Slice((y - 1) * image.Stride, image.Stride).CopyTo(row);
                        continue;
                    }
                    byte r, g, b;
                    if (y < wallTop) { r = 120; g = 170; b = 230; }
                    else if (y < horizon) { r = wall; g = wall; b = (byte)(wall / 2); }
                    else { r = shade; g = (byte)(shade / 2); b = 30; }
                    for (int x = 0; x + bpp <= row.Length; x += bpp)
                    {
                        row[x] = r;
                        if (bpp >= 3) { row[x + 1] = g; row[x + 2] = b; }
                        if (bpp == 4) row[x + 3] = 255;
                    }
                }
            }
        }

        float DistanceAhead()
        {
            double h = headingDeg * Math.PI / 180.0;
            double dx = Math.Sin(h), dz = Math.Cos(h);
            double tx = dx > 1e-6 ? (HalfRoom - position.X) / dx : dx < -1e-6 ? (-HalfRoom - position.X) / dx : 1e9;
            double tz = dz > 1e-6 ? (HalfRoom - position.Z) / dz : dz < -1e-6 ? (-HalfRoom - position.Z) / dz : 1e9;
            return (float)Math.Min(tx, tz);
        }

        public void WriteSensors(ref Sensors s)
        {
            s.Pose.Position = position;
            s.Pose.Rotation = Quat.FromYawDeg(headingDeg);
            s.Grid.Position = position;
            s.Grid.RotationDeg = new Vec3(0, headingDeg, 0);
            s.HeadMotion.Velocity = velocity;
            s.Eye.RotationDeg = eye;
            for (int i = 0; i < events.StatusCount; i++)
            {
                ActionStatus st = events.GetStatus(i);
                s.AddStatus(st.ActionId, st.State);
            }
            for (int i = 0; i < events.CollisionCount; i++)
            {
                Collision c = events.GetCollision(i);
                s.AddCollision(c.ActionId, c.ColliderId);
            }
            events.ClearEvents();
        }

        /// <summary>Commands received (applied or rejected).</summary>
        public long CommandCount { get; private set; }

        public bool Apply(MotorCommand c)
        {
            CommandCount++;
            if (!c.IsWellFormed)
                return false;
            switch (c.Kind)
            {
                case CommandKind.Move:
                    if (c.Arg1 < 0f || c.Arg1 > 100f)
                        return false;
                    StartMove(c.ActionId, c.Arg0, c.Arg1);
                    return true;
                case CommandKind.MoveTo:
                {
                    float dx = c.Arg0 - position.X, dz = c.Arg2 - position.Z;
                    if (Math.Abs(c.Arg0) > HalfRoom || Math.Abs(c.Arg2) > HalfRoom)
                        return false;
                    float heading = (float)(Math.Atan2(dx, dz) * 180.0 / Math.PI);
                    StartMove(c.ActionId, heading, (float)Math.Sqrt(dx * dx + dz * dz));
                    return true;
                }
                case CommandKind.Turn:
                    if (Math.Abs(c.Arg0) > 3600f)
                        return false;
                    AbortRunning();
                    motion = Motion.Turn;
                    actionId = c.ActionId;
                    remaining = c.Arg0;
                    events.AddStatus(actionId, ActionState.InExecution);
                    return true;
                case CommandKind.CancelMove:
                    AbortRunning();
                    events.AddStatus(c.ActionId, ActionState.Finished);
                    return true;
                case CommandKind.EyeMovement:
                    eye = new Vec3(c.Arg0, c.Arg1, c.Arg2);
                    events.AddStatus(c.ActionId, ActionState.Finished);
                    return true;
                case CommandKind.EnvironmentReset:
                case CommandKind.TrialReset:
                    AbortRunning();
                    Reset();
                    return true;
                default:
                    // Fixation, grasp, point, interact, release: nothing to do them with in
                    // this room.
                    events.AddStatus(c.ActionId, ActionState.Aborted);
                    return true;
            }
        }

        void StartMove(uint action, float heading, float distance)
        {
            AbortRunning();
            motion = Motion.Move;
            actionId = action;
            remaining = distance;
            moveHeadingDeg = ((heading % 360f) + 360f) % 360f;
            events.AddStatus(actionId, ActionState.InExecution);
        }

        void AbortRunning()
        {
            if (motion != Motion.None)
                events.AddStatus(actionId, ActionState.Aborted);
            motion = Motion.None;
        }

        public void Step(float dt)
        {
            velocity = new Vec3(0, 0, 0);
            if (motion == Motion.Turn)
            {
                float step = Math.Min(TurnSpeedDeg * dt, Math.Abs(remaining)) * Math.Sign(remaining);
                headingDeg = ((headingDeg + step) % 360f + 360f) % 360f;
                remaining -= step;
                if (Math.Abs(remaining) <= 1e-3f)
                {
                    events.AddStatus(actionId, ActionState.Finished);
                    motion = Motion.None;
                }
                else
                    events.AddStatus(actionId, ActionState.Rotating);
            }
            else if (motion == Motion.Move)
            {
                headingDeg = moveHeadingDeg;
                float step = Math.Min(Speed * dt, remaining);
                double h = moveHeadingDeg * Math.PI / 180.0;
                float nx = position.X + (float)Math.Sin(h) * step;
                float nz = position.Z + (float)Math.Cos(h) * step;
                uint collider = 0;
                float limit = HalfRoom - Radius;
                if (nz > limit) { nz = limit; collider = WallCollider; }
                if (nx > limit) { nx = limit; collider = WallCollider + 1; }
                if (nz < -limit) { nz = -limit; collider = WallCollider + 2; }
                if (nx < -limit) { nx = -limit; collider = WallCollider + 3; }
                float walked = (float)Math.Sqrt((nx - position.X) * (nx - position.X) + (nz - position.Z) * (nz - position.Z));
                Walked += walked;
                velocity = new Vec3((nx - position.X) / dt, 0, (nz - position.Z) / dt);
                position = new Vec3(nx, position.Y, nz);
                remaining -= step;
                if (collider != 0)
                {
                    Collisions++;
                    events.AddCollision(actionId, collider);
                    events.AddStatus(actionId, ActionState.Finished);
                    motion = Motion.None;
                }
                else if (remaining <= 1e-4f)
                {
                    events.AddStatus(actionId, ActionState.Finished);
                    motion = Motion.None;
                }
                else
                    events.AddStatus(actionId, ActionState.Walking);
            }
        }
    }

    public static class ConsoleHost
    {
        const string Usage =
            "usage: VrsyncConsoleHost.exe --config FILE [--cycles N] [--connect-timeout SECONDS] [--log FILTER]";

        public static int Main(string[] args)
        {
            string config = null, logFilter = null;
            int cycles = 100;
            double connectTimeoutS = -1;
            try
            {
                for (int i = 0; i < args.Length; i++)
                {
                    switch (args[i])
                    {
                        case "--config": config = args[++i]; break;
                        case "--cycles": cycles = int.Parse(args[++i]); break;
                        case "--connect-timeout": connectTimeoutS = double.Parse(args[++i], System.Globalization.CultureInfo.InvariantCulture); break;
                        case "--log": logFilter = args[++i]; break;
                        default: throw new ArgumentException("unknown argument " + args[i]);
                    }
                }
                if (config == null)
                    throw new ArgumentException("--config is required");
            }
            catch (Exception e)
            {
                Console.Error.WriteLine("VrsyncConsoleHost: " + e.Message + "\n" + Usage);
                return 2;
            }
            try
            {
                return Run(config, cycles, connectTimeoutS, logFilter);
            }
            catch (VrsyncException e)
            {
                Console.Error.WriteLine("VrsyncConsoleHost: error: " + e.Message);
                return 1;
            }
        }

        static int Run(string configPath, int cycles, double connectTimeoutS, string logFilter)
        {
            if (logFilter != null)
                Host.InitLogging(logFilter);
            using (var host = new Host(configPath))
            {
                HostInfo info = host.Info;
                Console.Error.WriteLine(string.Format(
                    "vrsync console host (libvrsync_host {0}): {1} agents, {2}, waiting for them",
                    Host.LibraryVersion, info.AgentCount, info.SyncMode != 0 ? "sync" : "async"));
                if (info.Transport == Transport.Tcp)
                    Console.Error.WriteLine("tcp_port=" + info.TcpPort); // agents connect here
                host.WaitForAgents(connectTimeoutS);

                var bodies = new List<KinematicBody>();
                foreach (var a in host.Agents)
                {
                    float x = -2f + 4f * (a.Id % 2), z = -2f + 1.5f * (a.Id / 2);
                    bodies.Add(new KinematicBody(a.Id, new Vec3(x, 0, z), 90f * a.Id));
                }
                var driver = new SyncDriver(host, bodies.ConvertAll(b => (IAgentBody)b),
                    line => Console.Error.WriteLine(line));

                var clock = Stopwatch.StartNew();
                for (int c = 0; c < cycles; c++)
                {
                    driver.Update(); // frame 1
                    driver.Update(); // frame 2
                    if (c == 0 || (c + 1) % 25 == 0)
                        Console.Error.WriteLine(string.Format("cycle {0}: {1} commands so far",
                            driver.LastCycle.Cycle, driver.CommandsApplied + driver.CommandsRejected));
                }
                double wall = clock.Elapsed.TotalSeconds;
                HostStats stats = host.Stats;

                Console.WriteLine("cycles=" + stats.Cycles);
                Console.WriteLine("stop_timeouts=" + stats.StopTimeouts);
                Console.WriteLine("agent_timeouts=" + stats.AgentTimeouts);
                Console.WriteLine("slow_stops=" + stats.SlowStops);
                Console.WriteLine("leaves=" + stats.Leaves);
                Console.WriteLine("late_batches=" + stats.LateBatches);
                Console.WriteLine("commands_received=" + stats.CommandsReceived);
                Console.WriteLine("commands_applied=" + driver.CommandsApplied);
                Console.WriteLine("commands_rejected=" + driver.CommandsRejected);
                Console.WriteLine("frames_undelivered=" + stats.FramesUndelivered);
                foreach (var b in bodies)
                {
                    Console.WriteLine(string.Format("agent{0}_commands={1}", b.AgentId, b.CommandCount));
                    Console.WriteLine(string.Format("agent{0}_walked_m={1:0.###}", b.AgentId, b.Walked));
                    Console.WriteLine(string.Format("agent{0}_collisions={1}", b.AgentId, b.Collisions));
                    Console.WriteLine(string.Format("agent{0}_position={1}", b.AgentId, b.Position));
                }
                Console.WriteLine(string.Format("wall_s={0:0.###}", wall));
                Console.WriteLine(string.Format("cycles_per_s={0:0.#}", stats.Cycles / wall));
            }
            return 0;
        }
    }
}
