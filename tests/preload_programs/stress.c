/*
 * A threaded stress of librollcam_preload's handle lifetime (tests/test_preload_hardening.py builds and runs it
 * under the library, also built with AddressSanitizer and ThreadSanitizer). Usage: stress DEVICE SECONDS.
 *
 * races:  8 threads on one shared fd: ioctl, dup+ioctl+close, dup2, fstat, poll, and close of the fd with a new
 *         open put in its place (the attack that corrupted the heap: two closes freeing one handle, an ioctl
 *         on a freed one).
 * closing: a thread streams (blocking DQBUF/QBUF) while another closes the fd under it.
 * fork:   a child works on the parent's open file (its own connection) while the parent streams.
 * storm:  4 threads open, ask and close as fast as they can.
 * Usage: stress DEVICE SECONDS [PHASES] (PHASES: letters of r(aces) c(losing) f(ork) s(torm), p (poll in the
 * races); default all). ThreadSanitizer runs leave p out: its poll interceptor, preloaded before the library,
 * ignores the synchronisation of what it calls (a blocking call), so the races would be false reports.
 * Exits 0 with a JSON line of counts; 1 when a call failed in a way Linux would not allow.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static const char *dev;
static double seconds;
static atomic_int shared_fd;
static atomic_long calls, unexpected;
static int with_poll;

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

/* Errors a racing program may see (the fd closed, reused, or the queue another's); anything else counts. */
static void check(int r, const char *what) {
    atomic_fetch_add(&calls, 1);
    if (r >= 0 || errno == EBADF || errno == ENOTTY || errno == EBUSY || errno == EINVAL || errno == EAGAIN ||
        errno == EINTR)
        return;
    fprintf(stderr, "stress: %s: %s\n", what, strerror(errno));
    atomic_fetch_add(&unexpected, 1);
}

static void *racer(void *arg) {
    unsigned seed = (unsigned)(size_t)arg;
    double end = now() + seconds;
    while (now() < end) {
        int fd = atomic_load(&shared_fd), d;
        struct v4l2_capability cap;
        struct v4l2_format fmt = {.type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
        struct stat st;
        struct pollfd p = {fd, POLLIN | POLLPRI, 0};
        switch (rand_r(&seed) % 6) {
        case 0:
            check(ioctl(fd, VIDIOC_QUERYCAP, &cap), "QUERYCAP");
            break;
        case 1:
            if ((d = dup(fd)) >= 0) {
                check(ioctl(d, VIDIOC_G_FMT, &fmt), "G_FMT on a dup");
                close(d);
            }
            break;
        case 2: {
            int fresh = open(dev, O_RDWR | O_NONBLOCK);
            check(fresh, "open");
            if (fresh >= 0)
                close(atomic_exchange(&shared_fd, fresh));
            break;
        }
        case 3:
            d = fcntl(fd, F_DUPFD_CLOEXEC, 900 + (int)(size_t)arg);
            if (d >= 0) {
                check(dup2(fd, d), "dup2");
                check(ioctl(d, VIDIOC_QUERYCAP, &cap), "QUERYCAP on a dup2");
                close(d);
            }
            break;
        case 4:
            fstat(fd, &st);
            break;
        default:
            if (with_poll)
                poll(&p, 1, 0);
            else
                check(ioctl(fd, VIDIOC_G_FMT, &fmt), "G_FMT");
        }
    }
    return NULL;
}

static int start_stream(int fd, int count) {
    struct v4l2_requestbuffers rb = {.count = (unsigned)count, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE,
                                     .memory = V4L2_MEMORY_MMAP};
    if (ioctl(fd, VIDIOC_REQBUFS, &rb) < 0)
        return -1;
    for (unsigned i = 0; i < rb.count; i++) {
        struct v4l2_buffer b = {.index = i, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE, .memory = V4L2_MEMORY_MMAP};
        if (ioctl(fd, VIDIOC_QBUF, &b) < 0)
            return -1;
    }
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    return ioctl(fd, VIDIOC_STREAMON, &type);
}

/* DQBUF/QBUF until the fd goes (closed by another thread) or n frames. */
static void *streamer(void *arg) {
    int fd = (int)(size_t)arg;
    for (int n = 0; n < 1000; n++) {
        struct v4l2_buffer b = {.type = V4L2_BUF_TYPE_VIDEO_CAPTURE, .memory = V4L2_MEMORY_MMAP};
        if (ioctl(fd, VIDIOC_DQBUF, &b) < 0 || ioctl(fd, VIDIOC_QBUF, &b) < 0)
            break;
        atomic_fetch_add(&calls, 2);
    }
    return NULL;
}

static void closing(int rounds) {
    unsigned seed = 7;
    for (int i = 0; i < rounds; i++) {
        int fd = open(dev, O_RDWR);
        if (fd < 0 || start_stream(fd, 2) < 0) {
            check(-1, "stream for closing");
            if (fd >= 0)
                close(fd);
            continue;
        }
        pthread_t t;
        pthread_create(&t, NULL, streamer, (void *)(size_t)fd);
        usleep((useconds_t)(rand_r(&seed) % 80000));
        close(fd); /* the streamer may be blocked in DQBUF on it: it finishes with the handle it holds */
        pthread_join(t, NULL);
    }
}

static int forked(void) {
    int fd = open(dev, O_RDWR);
    if (fd < 0 || start_stream(fd, 3) < 0)
        return 1;
    pid_t pid = fork();
    if (pid == 0) {
        struct v4l2_capability cap;
        for (int i = 0; i < 200; i++)
            if (ioctl(fd, VIDIOC_QUERYCAP, &cap) < 0)
                _exit(3);
        _exit(0);
    }
    pthread_t t;
    pthread_create(&t, NULL, streamer, (void *)(size_t)fd);
    int status = 0;
    waitpid(pid, &status, 0);
    usleep(100000);
    close(fd);
    pthread_join(t, NULL);
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        fprintf(stderr, "stress: the forked child's ioctls failed (status %d)\n", status);
        return 1;
    }
    return 0;
}

static void *stormer(void *arg) {
    (void)arg;
    double end = now() + seconds / 2;
    while (now() < end) {
        int fd = open(dev, O_RDWR);
        check(fd, "open in the storm");
        if (fd < 0)
            continue;
        struct v4l2_capability cap;
        check(ioctl(fd, VIDIOC_QUERYCAP, &cap), "QUERYCAP in the storm");
        close(fd);
    }
    return NULL;
}

int main(int argc, char **argv) {
    if (argc != 3 && argc != 4) {
        fprintf(stderr, "usage: stress DEVICE SECONDS [PHASES]\n");
        return 2;
    }
    const char *phases = argc == 4 ? argv[3] : "rcfsp";
    with_poll = strchr(phases, 'p') != NULL;
    dev = argv[1];
    seconds = atof(argv[2]);
    atomic_store(&shared_fd, open(dev, O_RDWR | O_NONBLOCK));
    if (atomic_load(&shared_fd) < 0) {
        perror("stress: open");
        return 1;
    }
    pthread_t t[8];
    for (int i = 0; strchr(phases, 'r') && i < 8; i++)
        pthread_create(&t[i], NULL, racer, (void *)(size_t)(i + 1));
    for (int i = 0; strchr(phases, 'r') && i < 8; i++)
        pthread_join(t[i], NULL);
    close(atomic_load(&shared_fd));
    if (strchr(phases, 'c'))
        closing(6);
    int fork_failed = strchr(phases, 'f') ? forked() : 0;
    for (int i = 0; strchr(phases, 's') && i < 4; i++)
        pthread_create(&t[i], NULL, stormer, NULL);
    for (int i = 0; strchr(phases, 's') && i < 4; i++)
        pthread_join(t[i], NULL);
    printf("{\"calls\": %ld, \"unexpected\": %ld, \"fork_failed\": %d}\n", atomic_load(&calls),
           atomic_load(&unexpected), fork_failed);
    return atomic_load(&unexpected) || fork_failed;
}
