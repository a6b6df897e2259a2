/*
 * An ioctl fuzzer for `rollcam run`'s device (tests/test_preload_sanitizers.py runs it under the library built
 * with AddressSanitizer, against the real server). Usage: fuzz DEVICE SEED COUNT.
 *
 * Each call picks a request (a known V4L2 one, a random 'V' one of random size and direction, or any 32-bit
 * number, sometimes sign-extended as an int-typed caller passes it) and an argument: random bytes, NULL, a
 * small integer, an unmapped page, a read-only page, or a struct ending at the edge of a mapping. Extended
 * control calls get random counts and control arrays. read() and poll() get garbage too, and the file is
 * reopened now and then. The program must not crash; it prints the counts as JSON.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

static const unsigned long known[] = {
    VIDIOC_QUERYCAP, VIDIOC_ENUM_FMT, VIDIOC_G_FMT, VIDIOC_S_FMT, VIDIOC_REQBUFS, VIDIOC_QUERYBUF, VIDIOC_QBUF,
    VIDIOC_EXPBUF, VIDIOC_DQBUF, VIDIOC_STREAMON, VIDIOC_STREAMOFF, VIDIOC_G_PARM, VIDIOC_S_PARM, VIDIOC_G_STD,
    VIDIOC_S_STD, VIDIOC_ENUMINPUT, VIDIOC_G_CTRL, VIDIOC_S_CTRL, VIDIOC_QUERYCTRL, VIDIOC_QUERYMENU,
    VIDIOC_G_INPUT, VIDIOC_S_INPUT, VIDIOC_TRY_FMT, VIDIOC_G_PRIORITY, VIDIOC_S_PRIORITY, VIDIOC_LOG_STATUS,
    VIDIOC_G_EXT_CTRLS, VIDIOC_S_EXT_CTRLS, VIDIOC_TRY_EXT_CTRLS, VIDIOC_ENUM_FRAMESIZES,
    VIDIOC_ENUM_FRAMEINTERVALS, VIDIOC_DQEVENT, VIDIOC_SUBSCRIBE_EVENT, VIDIOC_UNSUBSCRIBE_EVENT,
    VIDIOC_G_SELECTION, VIDIOC_S_SELECTION, VIDIOC_QUERY_EXT_CTRL, VIDIOC_CREATE_BUFS, VIDIOC_PREPARE_BUF,
    VIDIOC_ENUMSTD, VIDIOC_QUERYSTD, VIDIOC_G_TUNER, VIDIOC_CROPCAP, VIDIOC_G_CROP, VIDIOC_S_CROP,
};
#define N_KNOWN (sizeof known / sizeof known[0])

static uint64_t state;

static uint64_t next(void) { /* SplitMix64: the run is the seed's */
    uint64_t z = (state += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

int main(int argc, char **argv) {
    if (argc != 4) {
        fprintf(stderr, "usage: fuzz DEVICE SEED COUNT\n");
        return 2;
    }
    const char *dev = argv[1];
    state = strtoull(argv[2], NULL, 0);
    long count = atol(argv[3]);
    long page = sysconf(_SC_PAGESIZE);
    /* page 0: random bytes (read-write); page 1: no access; page 2: read-only; pages 3-4: a struct that runs
     * off the end of page 3 into the unmapped page 4. */
    char *area = mmap(NULL, (size_t)(5 * page), PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    static char rw[1 << 18]; /* more than any read() asks for below */
    struct v4l2_ext_control ctrls[64];
    if (area == MAP_FAILED)
        return 1;
    mprotect(area + page, (size_t)page, PROT_NONE);
    mprotect(area + 2 * page, (size_t)page, PROT_READ);
    munmap(area + 4 * page, (size_t)page);
    int fd = open(dev, O_RDWR | O_NONBLOCK);
    long ioctls = 0, ok = 0, efault = 0, reopened = 0, reads = 0, polls = 0;
    for (long i = 0; i < count; i++) {
        if (fd < 0 || next() % 300 == 0) {
            if (fd >= 0)
                close(fd);
            fd = open(dev, O_RDWR | O_NONBLOCK);
            reopened++;
            if (fd < 0)
                continue;
        }
        for (size_t k = 0; k < 4096; k += 8) {
            uint64_t v = next();
            memcpy(rw + k, &v, 8);
        }
        unsigned long request;
        uint64_t pick = next() % 8;
        if (pick < 4)
            request = known[next() % N_KNOWN];
        else if (pick < 7)
            request = _IOC((unsigned)(next() % 4), 'V', (unsigned)(next() % 256), (unsigned)(next() % 1024));
        else
            request = (unsigned)next();
        if (next() % 4 == 0)
            request = (unsigned long)(long)(int)request; /* as a caller with an int request passes it */
        unsigned size = _IOC_SIZE(request);
        void *arg;
        switch (next() % 10) {
        case 0: arg = NULL; break;
        case 1: arg = (void *)(uintptr_t)(next() % 4096); break;
        case 2: arg = area + page; break;
        case 3: arg = area + 2 * page; break;
        case 4: arg = area + 4 * page - (size ? size / 2 + 1 : 1); break;
        default: arg = rw;
        }
        unsigned nr = _IOC_NR(request);
        if (arg == rw && (nr == _IOC_NR(VIDIOC_G_EXT_CTRLS) || nr == _IOC_NR(VIDIOC_S_EXT_CTRLS) ||
                          nr == _IOC_NR(VIDIOC_TRY_EXT_CTRLS))) {
            struct v4l2_ext_controls *c = (void *)rw;
            c->count = (unsigned)(next() % 70);
            uint64_t where = next() % 4;
            c->controls = where == 0 ? ctrls : where == 1 ? NULL : where == 2 ? (void *)(area + page)
                                                                               : (void *)(area + 4 * page - 20);
            for (size_t k = 0; k < 64; k++) {
                ctrls[k].id = next() % 2 ? 0x00980900 + (unsigned)(next() % 64) : 0x009e0900 + (unsigned)(next() % 8);
                ctrls[k].size = (unsigned)(next() % 3 ? 0 : next() % 64);
                ctrls[k].value64 = (int64_t)next();
            }
        }
        int r = ioctl(fd, request, arg);
        ioctls++;
        ok += r >= 0;
        efault += r < 0 && errno == EFAULT;
        if (r >= 0 && request == VIDIOC_EXPBUF && arg == rw)
            close(((struct v4l2_exportbuffer *)rw)->fd);
        if (next() % 50 == 0) {
            char *where[] = {rw, NULL, area + page, area + 2 * page, area + 4 * page - 100};
            read(fd, where[next() % 5], (size_t)(next() % 200000));
            reads++;
        }
        if (next() % 50 == 0) {
            struct pollfd p = {fd, (short)next(), 0};
            void *where[] = {&p, NULL, area + page, area + 4 * page - 4};
            poll(where[next() % 4], 1, 0);
            polls++;
        }
    }
    if (fd >= 0)
        close(fd);
    printf("{\"ioctls\": %ld, \"ok\": %ld, \"efault\": %ld, \"reads\": %ld, \"polls\": %ld, \"reopened\": %ld}\n",
           ioctls, ok, efault, reads, polls, reopened);
    return 0;
}
