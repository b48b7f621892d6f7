// Edit-mode tests of the package, for Unity's Test Runner (Window > General > Test Runner,
// EditMode; add "com.vrsync.host" to "testables" in Packages/manifest.json to list them).
// They need the native plugin (Runtime/Plugins/x86_64/libvrsync_host.so) and no agent:
//   - the plugin loads and its structs match the C# binding's;
//   - a VrsyncCamera's image reaches the loaned frame top row first, R before G before B
//     (the check to run once on your graphics API: it renders red into the top half only).
// The repository's Mono harness runs the same tests against stubs of Unity's API.

using System;
using System.Diagnostics;
using System.IO;
using NUnit.Framework;
using UnityEngine;

namespace Vrsync.Tests
{
    public class VrsyncPackageTests
    {
        [Test]
        public void NativeLibraryLoadsAndMatchesTheBinding()
        {
            string[] rows = Host.CheckLayout();  // throws on a struct of another size
            Assert.IsTrue(rows.Length > 0, "no layout rows");
            Assert.IsFalse(string.IsNullOrEmpty(Host.LibraryVersion), "no library version");
        }

        [Test]
        public void CameraImageArrivesTopRowFirstInWireChannelOrder()
        {
            string dir = Path.Combine(Path.GetTempPath(), "vrsync-unity-test-" + Guid.NewGuid().ToString("N"));
            Directory.CreateDirectory(dir);
            string config = Path.Combine(dir, "vrsync.toml");
            string session = string.Format("unitytest{0}-{1}", Process.GetCurrentProcess().Id, DateTime.UtcNow.Ticks);
            File.WriteAllText(config, string.Join("\n", new[]
            {
                "session = \"" + session + "\"",
                "[sync]",
                "connect_timeout = 1.0",
                "[[agent]]",
                "id = 0",
                "[[agent.camera]]",
                "name = \"rgb\"",
                "width = 8",
                "height = 4",
                "format = \"rgb8\"",
                "[[agent.camera]]",
                "name = \"rgba\"",
                "width = 6",
                "height = 4",
                "format = \"rgba8\"",
                "",
            }));
            var body = new GameObject("vrsync test body");
            try
            {
                using (var host = new Host(config))
                {
                    CopyingBody copier = body.AddComponent<CopyingBody>();
                    VrsyncAgent agent = body.AddComponent<VrsyncAgent>();
                    agent.agentId = 0;
                    var cameras = new Camera[2];
                    string[] names = { "rgb", "rgba" };
                    for (int i = 0; i < 2; i++)
                    {
                        var eye = new GameObject("vrsync test " + names[i]);
                        eye.transform.SetParent(body.transform);
                        cameras[i] = eye.AddComponent<Camera>();
                        eye.AddComponent<VrsyncCamera>().cameraName = names[i];
                    }
                    agent.Bind(host.Agents[0]);
                    foreach (Camera cam in cameras)
                    {
                        // Black everywhere, then red into the top half of the viewport only.
                        cam.clearFlags = CameraClearFlags.SolidColor;
                        cam.backgroundColor = Color.black;
                        cam.rect = new Rect(0, 0, 1, 1);
                        cam.Render();
                        cam.backgroundColor = Color.red;
                        cam.rect = new Rect(0, 0.5f, 1, 0.5f);
                    }
                    SensorFrame frame = host.LoanFrame(0);
                    agent.BeginFrame(frame);
                    agent.WaitForCaptures();
                    agent.FinishFrame(frame);  // the body copies the images before the publish
                    host.Start();
                    for (int i = 0; i < 2; i++)
                    {
                        byte[] image = copier.Images[i];
                        int bpp = i == 0 ? 3 : 4, width = i == 0 ? 8 : 6;
                        for (int y = 0; y < 4; y++)
                        {
                            for (int x = 0; x < width; x++)
                            {
                                int p = (y * width + x) * bpp;
                                byte red = y < 2 ? (byte)255 : (byte)0;  // rows 0 and 1 are the top
                                string where = string.Format("camera {0} pixel ({1}, {2})", names[i], x, y);
                                Assert.AreEqual(red, image[p], where + " R");
                                Assert.AreEqual((byte)0, image[p + 1], where + " G");
                                Assert.AreEqual((byte)0, image[p + 2], where + " B");
                                if (bpp == 4)
                                    Assert.AreEqual((byte)255, image[p + 3], where + " A");
                            }
                        }
                    }
                }
            }
            finally
            {
                UnityEngine.Object.DestroyImmediate(body);
                Directory.Delete(dir, true);
            }
        }
    }

    /// <summary>A body that keeps a copy of each image of the frame it writes sensors for.</summary>
    public sealed class CopyingBody : MonoBehaviour, IVrsyncBody
    {
        public byte[][] Images = new byte[0][];

        public bool Apply(VrsyncAgent agent, MotorCommand command) { return true; }

        public void ApplyActions(VrsyncAgent agent, AgentReport report) { }

        public void WriteSensors(VrsyncAgent agent, SensorFrame frame, ref Sensors sensors)
        {
            Images = new byte[frame.ImageCount][];
            for (int i = 0; i < frame.ImageCount; i++)
                Images[i] = frame.GetImage(i).Pixels.ToArray();
        }
    }
}
