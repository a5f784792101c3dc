// Writes Runtime/Native/ZooNative.Functions.cs from zoo.h (Tools~/update-bindings.sh builds and
// runs it with Tests~/Header.cs, the header reader and C-to-C# mapping the binding check uses).
using System;
using System.IO;

namespace Zoo.Tests
{
    static class GenerateBindings
    {
        static int Main(string[] args)
        {
            if (args.Length != 2)
            {
                Console.Error.WriteLine("usage: generate-bindings.exe HEADER OUT");
                return 2;
            }
            var header = CHeader.Parse(File.ReadAllText(args[0]));
            File.WriteAllText(args[1], Mapping.Generate(header));
            Console.WriteLine("wrote " + args[1] + ": " + header.Functions.Count + " functions of C ABI version " + header.AbiVersion);
            return 0;
        }
    }
}
