// A minimal agent body for the vrsync sample scene: walks and turns on the ground plane as
// the agent commands (Move, Turn, MoveTo, CancelMove), one action at a time, and reports each
// action's state (Walking / Rotating, then Finished or Aborted) so agents like
// `vr-agent --policy wander` send their next command at once. Kinematic: it moves its
// Transform by Time.deltaTime (in sync mode exactly simulation_time_per_frame per cycle).

using UnityEngine;
using Vrsync;

namespace Vrsync.Samples
{
    [AddComponentMenu("vrsync/Samples/Walking Body")]
    public sealed class WalkingBody : MonoBehaviour, IVrsyncBody
    {
        [Tooltip("Walking speed, metres per second")]
        public float speed = 1.0f;

        [Tooltip("Turning speed, degrees per second")]
        public float turnSpeed = 180.0f;

        VrsyncAgent agent;
        uint actionId;
        bool running;
        float headingDeg;       // where the body faces (0 = +z, 90 = +x)
        float turnLeftDeg;      // still to turn
        Vector3 walkDirection;  // unit, on the ground plane
        float walkLeftM;        // still to walk

        public bool Apply(VrsyncAgent from, MotorCommand c)
        {
            agent = from;
            if (!c.IsWellFormed)
                return false;
            switch (c.Kind)
            {
                case CommandKind.Move:
                    Begin(c.ActionId, c.Arg0 - headingDeg, c.Arg0, c.Arg1);
                    return true;
                case CommandKind.Turn:
                    Begin(c.ActionId, c.Arg0, headingDeg + c.Arg0, 0);
                    return true;
                case CommandKind.MoveTo:
                {
                    Vector3 p = transform.position;
                    float dx = c.Arg0 - p.x, dz = c.Arg2 - p.z;
                    float heading = Mathf.Atan2(dx, dz) * Mathf.Rad2Deg;
                    Begin(c.ActionId, heading - headingDeg, heading, Mathf.Sqrt(dx * dx + dz * dz));
                    return true;
                }
                case CommandKind.CancelMove:
                    if (running)
                        agent.ReportStatus(actionId, ActionState.Aborted);
                    running = false;
                    return true;
                default:
                    return false;  // eyes, grasping, resets: not in this sample
            }
        }

        void Begin(uint id, float turnDeg, float headingAfterDeg, float distanceM)
        {
            if (running)
                agent.ReportStatus(actionId, ActionState.Aborted);  // a new action replaces it
            actionId = id;
            running = true;
            turnLeftDeg = Mathf.DeltaAngle(0, turnDeg);
            float rad = headingAfterDeg * Mathf.Deg2Rad;
            walkDirection = new Vector3(Mathf.Sin(rad), 0, Mathf.Cos(rad));
            walkLeftM = distanceM;
            agent.ReportStatus(actionId, turnLeftDeg != 0 ? ActionState.Rotating : ActionState.Walking);
        }

        public void ApplyActions(VrsyncAgent from, AgentReport report)
        {
            // This sample's config declares no [[agent.action]]; a body with channels reads
            // them here: ActionValue v = report.Action("torque"); if (v.HasValue) ... v.Values
        }

        public void WriteSensors(VrsyncAgent from, SensorFrame frame, ref Sensors sensors)
        {
            // The pose is set from the Transform already; add reward, vectors, head motion here.
        }

        void Update()
        {
            if (!running)
                return;
            float dt = Time.deltaTime;
            if (turnLeftDeg != 0)
            {
                float step = Mathf.Clamp(turnLeftDeg, -turnSpeed * dt, turnSpeed * dt);
                turnLeftDeg -= step;
                headingDeg += step;
                transform.rotation = Quaternion.Euler(0, headingDeg, 0);
                if (turnLeftDeg == 0 && walkLeftM > 0)
                    agent.ReportStatus(actionId, ActionState.Walking);
            }
            else if (walkLeftM > 0)
            {
                float step = Mathf.Min(walkLeftM, speed * dt);
                walkLeftM -= step;
                transform.position = transform.position + walkDirection * step;
            }
            if (turnLeftDeg == 0 && walkLeftM <= 0)
            {
                running = false;
                agent.ReportStatus(actionId, ActionState.Finished);
            }
        }
    }
}
