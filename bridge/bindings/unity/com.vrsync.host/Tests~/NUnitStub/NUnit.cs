// A stub of the few NUnit names the package's editor tests use (Tests/Editor), so the Mono
// harness can compile and run them (Tests~/NUnitStub/Runner.cs); in Unity they run on the
// Test Runner's NUnit. Not NUnit: only [Test] and the asserts used.

using System;

namespace NUnit.Framework
{
    [AttributeUsage(AttributeTargets.Method)]
    public sealed class TestAttribute : Attribute { }

    public sealed class AssertionException : Exception
    {
        public AssertionException(string message) : base(message) { }
    }

    public static class Assert
    {
        public static void IsTrue(bool condition, string message)
        {
            if (!condition)
                throw new AssertionException(message);
        }

        public static void IsFalse(bool condition, string message) { IsTrue(!condition, message); }

        public static void AreEqual(object expected, object actual, string message)
        {
            if (!Equals(expected, actual))
                throw new AssertionException(string.Format("{0}: expected {1}, was {2}", message, expected, actual));
        }

        public static void Fail(string message) { throw new AssertionException(message); }
    }
}
