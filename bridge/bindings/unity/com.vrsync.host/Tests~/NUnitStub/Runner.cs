// Runs every [Test] method of the assemblies named on the command line (the package's
// editor tests, compiled against the Unity and NUnit stubs); exit 0 when all passed.

using System;
using System.Reflection;
using NUnit.Framework;

static class Runner
{
    static int Main(string[] args)
    {
        int passed = 0, failed = 0;
        foreach (string path in args)
        {
            foreach (Type type in Assembly.LoadFrom(path).GetTypes())
            {
                foreach (MethodInfo m in type.GetMethods(BindingFlags.Instance | BindingFlags.Public))
                {
                    if (m.GetCustomAttributes(typeof(TestAttribute), false).Length == 0)
                        continue;
                    string name = type.Name + "." + m.Name;
                    try
                    {
                        m.Invoke(Activator.CreateInstance(type), null);
                        Console.WriteLine("ok    " + name);
                        passed++;
                    }
                    catch (TargetInvocationException e)
                    {
                        Console.WriteLine("FAIL  " + name + ": " + e.InnerException);
                        failed++;
                    }
                }
            }
        }
        Console.WriteLine(string.Format("{0} passed, {1} failed", passed, failed));
        return failed == 0 && passed > 0 ? 0 : 1;
    }
}
