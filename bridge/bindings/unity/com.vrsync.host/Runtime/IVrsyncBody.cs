// What a Unity scene does for one agent body: the parts of the original AgentScript that
// are not networking. Implement it on a MonoBehaviour of the agent's GameObject (or name
// that behaviour in VrsyncAgent.body); VrsyncHost calls it on the main thread.

namespace Vrsync
{
    /// <summary>
    /// The body of one agent: receives the agent's motor commands and channel actions (frame
    /// 2 of a cycle) and may add sensor data beside the pose and the images (frame 1).
    /// Report the state of the actions you run with <see cref="VrsyncAgent.ReportStatus"/>
    /// and collisions with <see cref="VrsyncAgent.ReportCollision"/>: they go out with the
    /// next frame (the example agents wait for <c>Finished</c>/<c>Aborted</c> before their
    /// next command). An exception thrown by one of these methods is logged and costs only
    /// that call (a command that threw counts as rejected); the session goes on.
    /// </summary>
    public interface IVrsyncBody
    {
        /// <summary>
        /// Frame 2: one motor command, in the order the agent sent them (the original
        /// <c>ProcessMsg</c>). Start the movement, turn, eye movement ...; move the body in
        /// your own <c>Update</c>/<c>FixedUpdate</c> (in sync mode every engine frame is one
        /// cycle of <c>simulation_time_per_frame</c>). Return false to reject it (unknown
        /// kind, NaN, out of range: <see cref="MotorCommand.IsWellFormed"/>); the agent sees
        /// the count in its next frame.
        /// </summary>
        bool Apply(VrsyncAgent agent, MotorCommand command);

        /// <summary>
        /// Frame 2, after the commands: the agent's channel actions of this cycle
        /// (<c>report.Action("torque")</c>; <see cref="ActionKind.None"/> when it sent none).
        /// Called every cycle the agent took part in, also when its config has no actions.
        /// </summary>
        void ApplyActions(VrsyncAgent agent, AgentReport report);

        /// <summary>
        /// Frame 1, after the images are in the frame and before it is published: the
        /// agent's vectors (<c>frame.Vector("joints")</c>: write all of it), reward, head
        /// motion, eye position. The pose is already set from the agent's Transform, and the
        /// statuses and collisions reported since the last frame are already added.
        /// </summary>
        void WriteSensors(VrsyncAgent agent, SensorFrame frame, ref Sensors sensors);
    }
}
