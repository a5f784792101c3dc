// The console test program of the Unity package (built and run by tests/unity.rs):
//   zoo-tests.exe check-bindings HEADER      the bindings against zoo.h (exit 1 on any difference)
//   zoo-tests.exe run VECTORS MODEL_DIR      every task through the wrappers against the Rust runtime's outputs
using System;
using System.IO;

namespace Zoo.Tests
{
    static class Program
    {
        static int Main(string[] args)
        {
            if (args.Length == 2 && args[0] == "check-bindings")
            {
                var h = CHeader.Parse(File.ReadAllText(args[1]));
                string summary;
                var problems = BindingCheck.Run(h, typeof(Zoo.Model).Assembly, out summary);
                foreach (var p in problems) Console.WriteLine("binding check: " + p);
                if (problems.Count > 0)
                {
                    Console.WriteLine("binding check: FAILED, " + problems.Count + " difference(s) between " + args[1] + " and the bindings (" + summary + ")");
                    return 1;
                }
                Console.WriteLine("binding check: the bindings match " + Path.GetFileName(args[1]) + ": " + summary);
                return 0;
            }
            if (args.Length == 3 && args[0] == "run")
            {
                return ConsoleTests.Run(new Vectors(args[1]), args[2]);
            }
            Console.Error.WriteLine("usage: zoo-tests.exe check-bindings HEADER | run VECTORS MODEL_DIR");
            return 2;
        }
    }
}
