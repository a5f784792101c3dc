"""PyTorch reference for `zoo bench train --model rtn`: the paper-size RTN training step
(K = 22 joints, D = 66, batch 32, 10 past frames, 30 transition frames + the target,
AMSGrad lr 5e-4, teacher forcing p = 0.2 per frame), with the same layer shapes and the same
per-frame operations as offline/models/rtn (frame/target/offset encoders, one fused LSTM gate matmul,
residual decoder, root integration, offsets recomputed in the graph, learned initial state).

Prints one JSON line per thread count: windows per second (median over repeats).
Run through scripts/bench_train_torch.sh, which installs the pinned PyTorch into a venv.
"""
import argparse, json, statistics, time
import torch
import torch.nn as nn
import torch.nn.functional as F

K, D, PAST, TRANS, B = 22, 66, 10, 30, 32
HU = 512


def mlp(sizes, last_act):
    layers = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2 or last_act:
            layers.append(nn.LeakyReLU(0.01))
    return nn.Sequential(*layers)


class Rtn(nn.Module):
    def __init__(self):
        super().__init__()
        self.frame = mlp([D, 512, 512], True)
        self.target = mlp([2 * D, 128, 128], True)
        self.offset = mlp([D, 128, 128], True)
        k = 1.0 / HU ** 0.5
        self.w_ih = nn.Parameter(torch.empty(4 * HU, 512).uniform_(-k, k))
        self.w_hh = nn.Parameter(torch.empty(4 * HU, HU).uniform_(-k, k))
        self.w_off = nn.Parameter(torch.empty(4 * HU, 128).uniform_(-k, k))
        self.w_tgt = nn.Parameter(torch.empty(4 * HU, 128).uniform_(-k, k))
        self.bias = nn.Parameter(torch.empty(4 * HU).uniform_(-k, k))
        self.decoder = mlp([HU, 256, 128, D], False)
        self.init = mlp([D, 512, 2 * HU], False)
        # Fixed normalisation constants, as OffsetTensors holds them.
        self.register_buffer("x_scale", torch.rand(D) + 0.5)
        self.register_buffer("v_scale", torch.rand(3) + 0.5)
        self.register_buffer("root_tile", torch.rand(3, D))

    def forward(self, x_known, roots, target_vec, target_term, teacher):
        fused = torch.cat([self.w_ih, self.w_hh, self.w_off], 1).t()
        gate_bias = self.target(target_vec) @ self.w_tgt.t() + self.bias
        hc = self.init(x_known[0])
        h, c = hc[:, :HU], hc[:, HU:]
        x, root = x_known[0], roots[0]
        outs = []
        for t in range(PAST - 1 + TRANS + 1):
            off = target_term - x * self.x_scale - root @ self.root_tile
            z = torch.cat([self.frame(x), h, self.offset(off)], 1) @ fused + gate_bias
            s = torch.sigmoid(z)
            i, f, o = s[:, :HU], s[:, HU:2 * HU], s[:, 3 * HU:]
            g = torch.tanh(z[:, 2 * HU:3 * HU])
            c = f * c + i * g
            h = o * torch.tanh(c)
            nxt = x + self.decoder(h)
            nt = t + 1
            if nt >= PAST:
                outs.append(nxt)
            if nt < PAST or (nt < len(x_known) and teacher[nt]):
                x, root = x_known[nt], roots[nt]
            else:
                root = root + nxt[:, :3] * self.v_scale
                x = nxt
        return torch.stack(outs, 1)


def run(threads, steps, repeats, seed):
    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    model = Rtn()
    opt = torch.optim.Adam(model.parameters(), lr=5e-4, amsgrad=True)
    frames = PAST + TRANS + 1
    x_known = [torch.randn(B, D) for _ in range(frames)]
    roots = [torch.randn(B, 3) for _ in range(frames)]
    target_vec = torch.randn(B, 2 * D)
    target_term = torch.randn(B, D)
    truth = torch.randn(B, TRANS + 1, D)
    gen = torch.Generator().manual_seed(seed)

    def step():
        teacher = (torch.rand(frames, generator=gen) < 0.2).tolist()
        pred = model(x_known, roots, target_vec, target_term, teacher)
        loss = F.mse_loss(pred, truth)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return loss.item()

    step()  # warm-up
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(steps):
            step()
        rates.append(steps * B / (time.perf_counter() - t0))
    return rates


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    for t in [int(s) for s in a.threads.split(",")]:
        rates = run(t, a.steps, a.repeats, a.seed)
        print(json.dumps({"framework": f"pytorch {torch.__version__}", "model": "rtn", "threads": t,
                          "batch": B, "windows_per_s_median": statistics.median(rates),
                          "windows_per_s": rates}), flush=True)


if __name__ == "__main__":
    main()
