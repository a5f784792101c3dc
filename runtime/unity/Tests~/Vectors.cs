// The vectors file tests/unity.rs writes: one array per line, `name f|i|s values...`, floats as
// the hex of their bits (read back exactly).
using System;
using System.Collections.Generic;
using System.Globalization;
using System.IO;
using System.Runtime.InteropServices;
using Zoo.Native;

namespace Zoo.Tests
{
    sealed class Vectors
    {
        readonly Dictionary<string, float[]> floats = new Dictionary<string, float[]>();
        readonly Dictionary<string, long[]> ints = new Dictionary<string, long[]>();
        readonly Dictionary<string, string[]> strings = new Dictionary<string, string[]>();

        public Vectors(string path)
        {
            foreach (var line in File.ReadAllLines(path))
            {
                var parts = line.Split(' ');
                if (parts.Length < 2) continue;
                var n = parts.Length - 2;
                switch (parts[1])
                {
                    case "f":
                        var f = new float[n];
                        for (int i = 0; i < n; i++) f[i] = BitConverter.ToSingle(BitConverter.GetBytes(uint.Parse(parts[i + 2], NumberStyles.HexNumber, CultureInfo.InvariantCulture)), 0);
                        floats.Add(parts[0], f);
                        break;
                    case "i":
                        var v = new long[n];
                        for (int i = 0; i < n; i++) v[i] = long.Parse(parts[i + 2], CultureInfo.InvariantCulture);
                        ints.Add(parts[0], v);
                        break;
                    case "s":
                        var s = new string[n];
                        Array.Copy(parts, 2, s, 0, n);
                        strings.Add(parts[0], s);
                        break;
                    default:
                        throw new FormatException("vectors: unknown type `" + parts[1] + "` on " + parts[0]);
                }
            }
        }

        public float[] F(string name)
        {
            float[] v;
            if (!floats.TryGetValue(name, out v)) throw new KeyNotFoundException("vectors: no float array `" + name + "`");
            return v;
        }

        public long[] L(string name)
        {
            long[] v;
            if (!ints.TryGetValue(name, out v)) throw new KeyNotFoundException("vectors: no int array `" + name + "`");
            return v;
        }

        public int[] I(string name)
        {
            return Array.ConvertAll(L(name), x => (int)x);
        }

        public int Int(string name)
        {
            return I(name)[0];
        }

        public string[] S(string name)
        {
            string[] v;
            if (!strings.TryGetValue(name, out v)) throw new KeyNotFoundException("vectors: no string array `" + name + "`");
            return v;
        }

        /// <summary>`name.roots` (14 floats a root, the C layout) as roots.</summary>
        public ZooRootMotion[] Roots(string name)
        {
            var f = F(name + ".roots");
            if (f.Length % 14 != 0) throw new FormatException(name + ".roots: " + f.Length + " floats is not whole roots");
            return MemoryMarshal.Cast<float, ZooRootMotion>(f.AsSpan()).ToArray();
        }

        public float[] Rotations(string name)
        {
            return F(name + ".rot");
        }
    }
}
