#!/usr/bin/python3
"""Hostile-input corpus: writes crafted inputs into OUT and runs the slimrt CLI on each.

    scripts/hostile_corpus.py --cli build/slimrt --out build/hostile [--big] [--table]

Each case gives a file (or a procedural name), the CLI arguments, the expected exit code and a
piece of the expected message. A case passes when the exit code matches, the message holds the
piece, the process was not killed by a signal and no partial output was left behind. The files
are generated on each run (about 20 MB, nothing is checked in). --big adds the slow cases (a
million coincident triangles). --table prints input class, exit code, first line of the message,
seconds and peak memory (ru_maxrss of the child) as markdown. Each case runs with a CPU-time
limit (--cpu-limit, 10 s of all threads' CPU) and a wall-clock limit (--wall-limit, 120 s), so a
hang fails its case instead of stalling the run. Run by ctest (HostileCorpus), so by ./test.sh.
"""
import argparse
import base64
import os
import resource
import signal
import struct
import subprocess
import sys
import threading
import time


def memory_budget():
    """Same rule as slim::memory_budget(): half of the physical memory (or the cgroup limit)."""
    phys = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    try:
        with open("/sys/fs/cgroup/memory.max") as f:
            cg = int(f.read().strip())
            phys = min(phys, cg)
    except (OSError, ValueError):
        pass
    return max(phys // 2, 256 << 20)


def write(out, name, data):
    path = os.path.join(out, name)
    with open(path, "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())
    return path


def gltf(body):
    return '{"asset":{"version":"2.0"},' + body + "}"


def cases(out, big):
    tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    n = 10 ** 6
    c = []

    def add(klass, args, code, msg, fsize=None, absent=None, vmem=None):
        c.append(dict(klass=klass, args=args, code=code, msg=msg, fsize=fsize, absent=absent,
                      vmem=vmem))

    # 1. depth
    p = write(out, "deep_array.gltf", gltf('"extras":' + "[" * n + "]" * n))
    add("glTF JSON nested 10^6 levels (arrays)", ["info", p], 1, "more than 1000 levels deep")
    p = write(out, "deep_object.gltf", gltf('"extras":' + '{"a":' * n + "0" + "}" * n))
    add("glTF JSON nested 10^6 levels (objects)", ["info", p], 1, "more than 1000 levels deep")
    js = gltf('"extras":' + "[" * 100000 + "]" * 100000).encode()
    js += b" " * (-len(js) % 4)
    glb = struct.pack("<III", 0x46546C67, 2, 20 + len(js)) + struct.pack("<II", len(js), 0x4E4F534A)
    p = write(out, "deep.glb", glb + js)
    add("GLB JSON chunk nested 10^5 levels", ["info", p], 1, "more than 1000 levels deep")

    # 2. integers and floats beyond their types
    p = write(out, "index_2p32.obj", tri + "f 4294967297 4294967298 4294967299\n")
    add("OBJ indices beyond 2^32", ["info", p], 1, "index_2p32.obj:4: vertex index out of range: '4294967297'")
    p = write(out, "index_zero.obj", tri + "f 1 2 0\n")
    add("OBJ index 0", ["info", p], 1, "expected a nonzero index from 1 to 3")
    p = write(out, "float_1e39.obj", "v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n")
    add("OBJ coordinate 1e39", ["info", p], 1, "float_1e39.obj:2: vertex coordinate")
    head = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
            "property double z\nelement face 1\nproperty list uchar int vertex_indices\n"
            "end_header\n")
    p = write(out, "ascii_1e300.ply", head + "0 0 0\n1e300 0 0\n0 1 0\n3 0 1 2\n")
    add("PLY ascii double 1e300", ["info", p], 1, "ascii_1e300.ply:11: vertex property 'x'")
    p = write(out, "ascii_1e999.ply", head + "0 0 0\n1e999 0 0\n0 1 0\n3 0 1 2\n")
    add("PLY ascii 1e999", ["info", p], 1, "overflows double")
    binhead = head.replace("ascii", "binary_little_endian").encode()
    body = struct.pack("<9d", 0, 0, 0, 1e300, 0, 0, 0, 1, 0) + struct.pack("<B3i", 3, 0, 1, 2)
    p = write(out, "binary_1e300.ply", binhead + body)
    add("PLY binary double 1e300", ["info", p], 1, "overflows float")
    p = write(out, "list_4e9.ply", head.replace("uchar int", "uint uint")
              + "0 0 0\n1 0 0\n0 1 0\n4294967295 0 1 2\n")
    add("PLY list count 2^32-1", ["info", p], 1, "list count 4294967295")

    b36 = "data:application/octet-stream;base64," + "A" * 48
    geo = ('"buffers":[{"byteLength":36,"uri":"%s"}],"bufferViews":[{"buffer":0,"byteLength":36}],'
           '"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3"}],'
           '"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],' % b36)
    p = write(out, "mesh_2p32.gltf", gltf(geo + '"nodes":[{"mesh":4294967296}]'))
    add("glTF node mesh index 2^32", ["info", p], 1, "expected an integer from 0 to 2147483647")
    p = write(out, "mesh_1e10.gltf", gltf(geo + '"nodes":[{"mesh":1e10}]'))
    add("glTF node mesh index 1e10", ["info", p], 1, "expected an integer from 0 to 2147483647")

    # 3. outputs
    add("render -o into a missing folder (scene missing too)",
        ["render", os.path.join(out, "missing.obj"), "-o", os.path.join(out, "nodir", "x.png")],
        1, "nodir' does not exist")
    add("bench --json into a missing folder",
        ["bench", "terrain:8", "--config", "bvh8-tri4v", "--json",
         os.path.join(out, "nodir", "x.json")], 1, "nodir' does not exist")
    cut = os.path.join(out, "cut.png")
    add("render PNG onto a full disk (16 KiB file size limit)",
        ["render", "terrain:64", "--res", "256x256", "-o", cut], 1,
        "File too large", fsize=16 << 10, absent=cut)
    cutx = os.path.join(out, "cut.exr")
    add("render EXR onto a full disk (16 KiB file size limit)",
        ["render", "terrain:64", "--res", "256x256", "-o", cutx], 1,
        "File too large", fsize=16 << 10, absent=cutx)

    # 4. memory
    nv = 99999  # a multiple of 3: 33333 triangles
    write(out, "inst.bin", struct.pack("<%df" % (3 * nv), *([0.0, 1.0, 2.0] * nv)))
    nodes = memory_budget() // (nv * 12) + 2  # the positions alone pass the budget
    p = write(out, "instances.gltf", gltf(
        '"buffers":[{"uri":"inst.bin","byteLength":%d}],'
        '"bufferViews":[{"buffer":0,"byteLength":%d}],'
        '"accessors":[{"bufferView":0,"componentType":5126,"count":%d,"type":"VEC3"}],'
        '"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"nodes":[%s]'
        % (12 * nv, 12 * nv, nv, ",".join(['{"mesh":0}'] * nodes))))
    add("glTF: %d nodes on one 10^5-vertex mesh" % nodes, ["info", p], 1, "mesh instances")
    add("verify --rays 2^40", ["verify", "sphere:1", "--rays", "1099511627776"], 1,
        "--rays 1099511627776 needs about")
    add("render --res 65536x65536",
        ["render", "terrain:8", "--res", "65536x65536", "-o", os.path.join(out, "huge.png")], 1,
        "4294967296 pixels need about")

    # 6. out of memory: the step and the scene, not "std::bad_alloc"
    add("render terrain:2048 in 1.5 GB of address space",
        ["render", "terrain:2048", "--res", "64x64", "--threads", "1", "-o",
         os.path.join(out, "oom.png")], 1, "out of memory while building terrain:2048",
        vmem=1500000 * 1024)

    # 5. verify far from the origin
    for radius in (1e3, 1e9):
        o = 4e6
        vs = "".join("v %.9g %.9g %.9g\n" % (o + (radius if i & 1 else -radius),
                                             o + (radius if i & 2 else -radius),
                                             o + (radius if i & 4 else -radius)) for i in range(8))
        p = write(out, "cube_%g.obj" % radius,
                  vs + "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n")
        add("verify: closed cube at 4e6 offset, radius %g" % radius,
            ["verify", p, "--config", "bvh8-tri4v,bvh8-pairs", "--rays", "30000"], 0,
            "no leaks")

    # 6. messages
    add("torus:5", ["info", "torus:5"], 1, "even integer from 6 to 16384")
    p = write(out, "stride.gltf", gltf(
        '"buffers":[{"byteLength":4,"uri":"data:application/octet-stream;base64,AAAAAA=="}],'
        '"bufferViews":[{"buffer":0,"byteLength":4,"byteStride":256}]'))
    add("glTF byteStride 256", ["info", p], 1, "expected a multiple of 4 from 4 to 252")
    p = write(out, "short_uri.gltf", gltf(
        '"buffers":[{"byteLength":4000,"uri":"data:application/octet-stream;base64,%s"}]'
        % base64.b64encode(bytes(300)).decode()))
    add("glTF data URI shorter than byteLength", ["info", p], 1,
        "does not decode to its byteLength")
    os.makedirs(os.path.join(out, "folder.bin"), exist_ok=True)
    p = write(out, "folder_buffer.gltf", gltf('"buffers":[{"byteLength":4,"uri":"folder.bin"}]'))
    add("glTF buffer that is a folder", ["info", p], 1, "not a regular file")

    # 7. degenerate stacks: 10^5 coincident triangles traced by 65536 rays (each of them tested
    # every triangle of the stack before duplicates were dropped: about 40 s of CPU)
    p = write(out, "stack_1e5.obj", tri + "f 1 2 3\n" * 10 ** 5)
    add("10^5 coincident triangles (render 256x256)",
        ["render", p, "--res", "256x256", "--bounces", "0", "-o",
         os.path.join(out, "stack_1e5.png")], 0, "left out: 99999 duplicate triangles")
    # A stack of 10^5 coincident quads in a grid format: the grid finder's cell adjacency took
    # valence^2 steps at its four vertices (about 25 s of CPU for 4 x 10^4 quads)
    p = write(out, "quad_stack_1e5.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n" +
              "f 1 2 3 4\n" * 10 ** 5)
    add("10^5 coincident quads, grid (render 16x16)",
        ["render", p, "--config", "grid", "--res", "16x16", "--bounces", "0", "-o",
         os.path.join(out, "quad_stack.png")], 0, "left out: 199998 duplicate triangles")
    if big:
        p = write(out, "stack_1m.obj", tri + "f 1 2 3\n" * n)
        add("10^6 coincident triangles (render 16x16)",
            ["render", p, "--res", "16x16", "--bounces", "0", "-o",
             os.path.join(out, "stack.png")], 0, "left out: 999999 duplicate triangles")
    return c


def run(cli, case, cpu_limit, wall_limit):
    def limits():
        # A hang that computes is stopped by SIGXCPU (CPU time of all threads), one that waits by
        # the wall-clock timer below: either fails the case instead of stalling the test run.
        resource.setrlimit(resource.RLIMIT_CPU, (cpu_limit, cpu_limit + 1))
        if case["fsize"]:
            resource.setrlimit(resource.RLIMIT_FSIZE, (case["fsize"], case["fsize"]))
        if case["vmem"]:
            resource.setrlimit(resource.RLIMIT_AS, (case["vmem"], case["vmem"]))

    t0 = time.monotonic()
    proc = subprocess.Popen([cli] + case["args"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, preexec_fn=limits,
                            start_new_session=True)
    # The whole process group: a child holding the output pipe would keep read() waiting.
    timer = threading.Timer(wall_limit, lambda: os.killpg(proc.pid, signal.SIGKILL))
    timer.start()
    err = proc.stdout.read().decode(errors="replace")
    _, status, usage = os.wait4(proc.pid, 0)
    timer.cancel()
    proc.returncode = os.waitstatus_to_exitcode(status)
    seconds = time.monotonic() - t0
    code = proc.returncode
    problems = []
    if code == -signal.SIGXCPU:
        problems.append("more than %d s of CPU time (SIGXCPU)" % cpu_limit)
    elif code == -signal.SIGKILL and seconds >= wall_limit:
        problems.append("still running after %d s (killed)" % wall_limit)
    elif code < 0:
        problems.append("killed by signal %s" % signal.Signals(-code).name)
    elif code != case["code"]:
        problems.append("exit code %d, expected %d" % (code, case["code"]))
    if case["msg"] and case["msg"] not in err:
        problems.append("message lacks %r" % case["msg"])
    if case["absent"]:
        folder = os.path.dirname(case["absent"])
        left = [f for f in os.listdir(folder)
                if os.path.basename(case["absent"]) in f]
        if left:
            problems.append("left behind: %s" % left)
    lines = [l for l in err.splitlines() if l.strip()]
    first = next((l for l in lines if "error" in l), lines[-1] if lines else "")
    return dict(code=code, seconds=seconds, peak_mb=usage.ru_maxrss / 1024.0, first=first,
                problems=problems)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cli", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--big", action="store_true")
    ap.add_argument("--table", action="store_true")
    ap.add_argument("--cpu-limit", type=int, default=10,
                    help="CPU seconds per case (all threads); more fails the case (default 10)")
    ap.add_argument("--wall-limit", type=int, default=120,
                    help="wall-clock seconds per case before it is killed (default 120)")
    # Sanitizer builds reserve terabytes of shadow address space at start-up: an address-space
    # limit kills them before main(), so those cases are skipped (and said so).
    ap.add_argument("--no-address-limit", action="store_true")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    failed = 0
    # The limits themselves: a busy loop must end by SIGXCPU, a sleep by the timer.
    probe = dict(klass="limit probe", args=[], code=0, msg="", fsize=None, absent=None, vmem=None)
    for script, limits, expect in (("while :; do :; done", (1, 30), "SIGXCPU"),
                                   ("sleep 30", (10, 1), "killed")):
        r = run("/bin/sh", dict(probe, args=["-c", script]), *limits)
        if not any(expect in p for p in r["problems"]) or r["seconds"] > 15:
            print("FAIL the per-case limit did not stop '%s': %s" % (script, r["problems"]))
            failed += 1
    rows = []
    for case in cases(a.out, a.big):
        if a.no_address_limit and case.get("vmem"):
            print("skip %s: a sanitizer build cannot run under an address-space limit" %
                  case["klass"])
            continue
        r = run(a.cli, case, a.cpu_limit, a.wall_limit)
        rows.append((case, r))
        if r["problems"]:
            failed += 1
            print("FAIL %s: %s\n     %s" % (case["klass"], "; ".join(r["problems"]), r["first"]))
        else:
            print("ok   %s (exit %d, %.2f s, %.0f MB)" % (case["klass"], r["code"], r["seconds"],
                                                        r["peak_mb"]))
    if a.table:
        print("\n| input | exit | message | time (s) | peak memory (MB) |")
        print("| --- | ---: | --- | ---: | ---: |")
        for case, r in rows:
            msg = r["first"].replace("|", "\\|")
            if len(msg) > 160:
                msg = msg[:157] + "..."
            print("| %s | %d | %s | %.2f | %.0f |" % (case["klass"], r["code"], msg, r["seconds"],
                                                     r["peak_mb"]))
    print("%d of %d cases failed" % (failed, len(rows)))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
