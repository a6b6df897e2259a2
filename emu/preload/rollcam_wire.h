/*
 * The wire format between librollcam_preload (rollcam_preload.c) and its device server
 * (rollcam.emu.v4l2.server): the one definition. rollcam/emu/preload/wire.py reads this file, so it keeps to
 * a small subset of C: `#define ROLLCAM_WIRE_NAME number` lines, one `enum rollcam_op` of `OP_NAME = number`
 * members, and `struct rollcam_NAME { ... };` of fixed-width integer fields (uint32_t, int32_t, uint64_t,
 * int64_t), packed without padding in native byte order. Change anything here and ROLLCAM_WIRE_VERSION goes up.
 *
 * A connection is one open file. It starts with a hello each way ({magic, version}); a side that sees another
 * magic or version writes one line naming both and ends the connection, so a library and a server from two
 * builds never exchange garbage. Then requests (a rollcam_req and `len` payload bytes), each answered at once
 * by a rollcam_rsp and `len` bytes, with file descriptors (readiness pipes, memfds) as SCM_RIGHTS.
 *
 * OP_OPEN   payload: the device path; a: open flags. result: the file's id; fds: ready pipe, event pipe.
 * OP_ATTACH a: a file's id (from OP_OPEN): this connection shares that open file (a forked child's own line).
 * OP_IOCTL  a: the request (32 bits, as the kernel compares it); payload: the argument's bytes (and the
 *           v4l2_ext_control array of the extended-control calls). The answer's bytes go back to the argument.
 * OP_MMAP   a: offset, b: length, c: prot | flags << 32. fds: the buffer's memfd; result: offset into it.
 * OP_READ   a: count. The answer's bytes are the data; result: their count.
 * OP_POLL   a: the events asked for, b: 1 when POLLIN may start read() I/O. result: the V4L2 poll mask.
 * OP_CLOSE  this connection leaves its file; the last connection to leave releases it (answered after).
 */
#ifndef ROLLCAM_WIRE_H
#define ROLLCAM_WIRE_H

#include <stdint.h>

#define ROLLCAM_WIRE_MAGIC 0x52435057
#define ROLLCAM_WIRE_VERSION 2
#define ROLLCAM_WIRE_MAX_PAYLOAD 65536
#define ROLLCAM_WIRE_MAX_FDS 2

enum rollcam_op {
    OP_OPEN = 1,
    OP_IOCTL = 2,
    OP_MMAP = 3,
    OP_READ = 4,
    OP_POLL = 5,
    OP_CLOSE = 6,
    OP_ATTACH = 7,
};

struct rollcam_hello {
    uint32_t magic;
    uint32_t version;
};

struct rollcam_req {
    uint32_t op;
    uint32_t len;
    uint64_t a;
    uint64_t b;
    uint64_t c;
};

struct rollcam_rsp {
    int64_t result;
    int32_t err;
    uint32_t len;
};

#endif
