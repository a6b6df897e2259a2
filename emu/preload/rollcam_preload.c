/*
 * librollcam_preload: emulated /dev/videoN device nodes for an unmodified program (LD_PRELOAD).
 *
 * The library interposes the libc calls a V4L2 client makes on the device paths named in
 * ROLLCAM_PRELOAD_DEVICES (comma-separated) and forwards them over a Unix socket (ROLLCAM_PRELOAD_SOCKET) to
 * the device server, rollcam.emu.v4l2.server, which holds all of the V4L2 semantics. This side stays thin:
 * it moves the ioctl argument's bytes, waits where a call blocks, and maps the buffers the server hands over
 * as memfds, so frames reach the program with no copy beyond the server's one fill.
 *
 * Each open() is one connection (one V4L2 file handle). The fd the program gets is an eventfd the server
 * keeps readable while a blocking DQBUF/read would return (a buffer done, not streaming, an error), so
 * poll/select/epoll on it work natively; a second, hidden eventfd is readable while events are pending.
 * poll/ppoll/select/pselect on an emulated fd ask the server for the exact V4L2 mask (POLLIN, POLLPRI,
 * POLLERR) and wait on those eventfds; epoll sees the first eventfd only (POLLIN).
 */
#define _GNU_SOURCE
#include <dirent.h>
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/sysmacros.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#define EXPORT __attribute__((visibility("default")))
#define MAX_FD 65536
#define MAX_DEVICES 16
#define MAX_EXT_CTRLS 1024
#define VIDEO_MAJOR 81

enum { OP_OPEN = 1, OP_IOCTL = 2, OP_MMAP = 3, OP_READ = 4, OP_POLL = 5, OP_CLOSE = 6 };

struct req { uint32_t op, len; uint64_t a, b, c; };
struct rsp { int64_t result; int32_t err; uint32_t len; };

struct handle {
    int ctl;             /* connection to the server: one V4L2 file handle */
    int evfd;            /* readable while events are pending */
    int readyfd;         /* the program's fd (first one opened) */
    int minor;
    int refs;            /* program fds referring to this handle (dup) */
    pid_t pid;           /* the process that opened it: a forked child closing its copy releases nothing */
    pthread_mutex_t lock;
};

static struct handle *table[MAX_FD];
static pthread_mutex_t table_lock = PTHREAD_MUTEX_INITIALIZER;
static char sock_path[108];
static char devices[MAX_DEVICES][64];
static int n_devices;
static int debug;
static char sysfs_root[PATH_MAX];  /* ROLLCAM_PRELOAD_SYSFS: a folder mirroring the /sys entries of the nodes */

/* ------------------------------------------------------------------------------------------ real calls */
#define REAL(ret, name, ...) \
    static ret (*real_##name)(__VA_ARGS__); \
    static void resolve_##name(void) { if (!real_##name) real_##name = dlsym(RTLD_NEXT, #name); }

REAL(int, open, const char *, int, ...)
REAL(int, open64, const char *, int, ...)
REAL(int, openat, int, const char *, int, ...)
REAL(int, openat64, int, const char *, int, ...)
REAL(int, __open_2, const char *, int)
REAL(int, __open64_2, const char *, int)
REAL(int, __openat_2, int, const char *, int)
REAL(int, __openat64_2, int, const char *, int)
REAL(int, close, int)
REAL(int, ioctl, int, unsigned long, ...)
REAL(void *, mmap, void *, size_t, int, int, int, off_t)
REAL(void *, mmap64, void *, size_t, int, int, int, off64_t)
REAL(ssize_t, read, int, void *, size_t)
REAL(ssize_t, __read_chk, int, void *, size_t, size_t)
REAL(ssize_t, write, int, const void *, size_t)
REAL(int, poll, struct pollfd *, nfds_t, int)
REAL(int, ppoll, struct pollfd *, nfds_t, const struct timespec *, const sigset_t *)
REAL(int, select, int, fd_set *, fd_set *, fd_set *, struct timeval *)
REAL(int, pselect, int, fd_set *, fd_set *, fd_set *, const struct timespec *, const sigset_t *)
REAL(int, dup, int)
REAL(int, dup2, int, int)
REAL(int, dup3, int, int, int)
REAL(int, fcntl, int, int, ...)
REAL(int, fcntl64, int, int, ...)
REAL(int, stat, const char *, struct stat *)
REAL(int, stat64, const char *, struct stat64 *)
REAL(int, lstat, const char *, struct stat *)
REAL(int, lstat64, const char *, struct stat64 *)
REAL(int, fstat, int, struct stat *)
REAL(int, fstat64, int, struct stat64 *)
REAL(int, fstatat, int, const char *, struct stat *, int)
REAL(int, fstatat64, int, const char *, struct stat64 *, int)
REAL(int, __xstat, int, const char *, struct stat *)
REAL(int, __xstat64, int, const char *, struct stat64 *)
REAL(int, __lxstat, int, const char *, struct stat *)
REAL(int, __lxstat64, int, const char *, struct stat64 *)
REAL(int, __fxstat, int, int, struct stat *)
REAL(int, __fxstat64, int, int, struct stat64 *)
REAL(int, __fxstatat, int, int, const char *, struct stat *, int)
REAL(int, __fxstatat64, int, int, const char *, struct stat64 *, int)
REAL(int, statx, int, const char *, int, unsigned int, struct statx *)
REAL(int, access, const char *, int)
REAL(int, faccessat, int, const char *, int, int)
REAL(int, eaccess, const char *, int)
REAL(int, euidaccess, const char *, int)
REAL(DIR *, opendir, const char *)
REAL(struct dirent *, readdir, DIR *)
REAL(struct dirent64 *, readdir64, DIR *)
REAL(int, closedir, DIR *)
REAL(long, syscall, long, ...)
REAL(FILE *, fopen, const char *, const char *)
REAL(FILE *, fopen64, const char *, const char *)
REAL(ssize_t, readlink, const char *, char *, size_t)

static void trace(const char *fmt, ...) {
    if (!debug)
        return;
    char buf[512];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    resolve_write();
    if (n > 0)
        real_write(2, buf, (size_t)n < sizeof buf ? (size_t)n : sizeof buf - 1);
}

__attribute__((constructor)) static void init(void) {
    /* Every real entry point up front, so that no path calls one not yet looked up. */
    resolve_open();
    resolve_open64();
    resolve_openat();
    resolve_openat64();
    resolve___open_2();
    resolve___open64_2();
    resolve___openat_2();
    resolve___openat64_2();
    resolve_close();
    resolve_ioctl();
    resolve_mmap();
    resolve_mmap64();
    resolve_read();
    resolve___read_chk();
    resolve_write();
    resolve_poll();
    resolve_ppoll();
    resolve_select();
    resolve_pselect();
    resolve_dup();
    resolve_dup2();
    resolve_dup3();
    resolve_fcntl();
    resolve_fcntl64();
    resolve_stat();
    resolve_stat64();
    resolve_lstat();
    resolve_lstat64();
    resolve_fstat();
    resolve_fstat64();
    resolve_fstatat();
    resolve_fstatat64();
    resolve___xstat();
    resolve___xstat64();
    resolve___lxstat();
    resolve___lxstat64();
    resolve___fxstat();
    resolve___fxstat64();
    resolve___fxstatat();
    resolve___fxstatat64();
    resolve_statx();
    resolve_access();
    resolve_faccessat();
    resolve_eaccess();
    resolve_euidaccess();
    resolve_opendir();
    resolve_readdir();
    resolve_readdir64();
    resolve_closedir();
    resolve_syscall();
    resolve_fopen();
    resolve_fopen64();
    resolve_readlink();
    const char *s = getenv("ROLLCAM_PRELOAD_SOCKET"), *d = getenv("ROLLCAM_PRELOAD_DEVICES");
    debug = getenv("ROLLCAM_PRELOAD_DEBUG") != NULL;
    const char *sys = getenv("ROLLCAM_PRELOAD_SYSFS");
    if (sys && strlen(sys) + 64 < sizeof sysfs_root)
        strcpy(sysfs_root, sys);
    if (!s || !d || strlen(s) >= sizeof sock_path)
        return;
    strcpy(sock_path, s);
    while (*d && n_devices < MAX_DEVICES) {
        const char *end = strchr(d, ',');
        size_t len = end ? (size_t)(end - d) : strlen(d);
        if (len > 0 && len < sizeof devices[0]) {
            memcpy(devices[n_devices], d, len);
            devices[n_devices++][len] = 0;
        }
        if (!end)
            break;
        d = end + 1;
    }
}

/* ---------------------------------------------------------------------------------------------- paths */
static int device_index(const char *path) {
    if (!path || !n_devices)
        return -1;
    for (int i = 0; i < n_devices; i++)
        if (strcmp(path, devices[i]) == 0)
            return i;
    return -1;
}

/* A /sys path of an emulated node (/sys/dev/char/81:N/..., /sys/class/video4linux/...) -> its file in the
 * mirror folder, when the mirror has it; any other path is returned as it is. */
static const char *redirect(const char *path, char *buf) {
    if (!path || !sysfs_root[0] || strncmp(path, "/sys/", 5) != 0)
        return path;
    if (strncmp(path, "/sys/dev/char/81:", 17) != 0 && strncmp(path, "/sys/class/video4linux", 22) != 0)
        return path;
    if ((size_t)snprintf(buf, PATH_MAX, "%s%s", sysfs_root, path + 4) >= PATH_MAX)
        return path;
    struct stat st;
    resolve_lstat();
    if (real_lstat(buf, &st) != 0)
        return path;
    trace("rollcam-preload: %s -> %s\n", path, buf);
    return buf;
}

#define REDIRECT(path) char rbuf_[PATH_MAX]; path = redirect(path, rbuf_)

static int minor_of(int index) {
    const char *p = devices[index] + strlen(devices[index]);
    while (p > devices[index] && p[-1] >= '0' && p[-1] <= '9')
        p--;
    return *p ? atoi(p) : index;
}

struct rsp;
struct req;
static int xfer(int ctl, const struct req *q, const void *payload, void *out, uint32_t cap, struct rsp *r,
                int *fds, int *nfds);

static struct handle *lookup(int fd) {
    if (fd < 0 || fd >= MAX_FD)
        return NULL;
    return __atomic_load_n(&table[fd], __ATOMIC_ACQUIRE);
}

static void attach(int fd, struct handle *h) {
    pthread_mutex_lock(&table_lock);
    h->refs++;
    __atomic_store_n(&table[fd], h, __ATOMIC_RELEASE);
    pthread_mutex_unlock(&table_lock);
}

/* Forget fd; the handle's connection closes (the server releases the file handle) with its last fd. */
static void detach(int fd) {
    struct handle *h = lookup(fd);
    if (!h)
        return;
    pthread_mutex_lock(&table_lock);
    __atomic_store_n(&table[fd], NULL, __ATOMIC_RELEASE);
    int last = --h->refs == 0;
    pthread_mutex_unlock(&table_lock);
    if (last) {
        /* Closing is synchronous, as on a kernel device: the file is released before close() returns. */
        struct req q = {OP_CLOSE, 0, 0, 0, 0};
        struct rsp r;
        if (getpid() == h->pid)
            xfer(h->ctl, &q, NULL, NULL, 0, &r, NULL, NULL);
        resolve_close();
        real_close(h->ctl);
        real_close(h->evfd);
        pthread_mutex_destroy(&h->lock);
        free(h);
    }
}

/* ------------------------------------------------------------------------------------------ transport */
static int send_all(int fd, const struct req *q, const void *payload) {
    struct iovec iov[2] = {{(void *)q, sizeof *q}, {(void *)payload, q->len}};
    size_t total = sizeof *q + q->len, sent = 0;
    while (sent < total) {
        struct msghdr m = {0};
        size_t skip = sent;
        struct iovec v[2];
        int n = 0;
        for (int i = 0; i < 2; i++) {
            if (skip >= iov[i].iov_len) {
                skip -= iov[i].iov_len;
                continue;
            }
            v[n].iov_base = (char *)iov[i].iov_base + skip;
            v[n++].iov_len = iov[i].iov_len - skip;
            skip = 0;
        }
        m.msg_iov = v;
        m.msg_iovlen = n;
        ssize_t r = sendmsg(fd, &m, MSG_NOSIGNAL);
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0)
            return -1;
        sent += (size_t)r;
    }
    return 0;
}

static int recv_all(int fd, void *buf, size_t len) {
    size_t got = 0;
    while (got < len) {
        ssize_t r = recv(fd, (char *)buf + got, len - got, 0);
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0)
            return -1;
        got += (size_t)r;
    }
    return 0;
}

/* One request and its answer. The answer's payload goes to out (up to cap bytes; the rest is dropped);
 * fds passed with it land in fds (up to 2). Returns 0, or -1 with errno ENODEV when the server is gone. */
static int xfer(int ctl, const struct req *q, const void *payload, void *out, uint32_t cap, struct rsp *r,
                int *fds, int *nfds) {
    if (send_all(ctl, q, payload) < 0) {
        errno = ENODEV;
        return -1;
    }
    union { char buf[CMSG_SPACE(2 * sizeof(int))]; struct cmsghdr align; } cm;
    struct iovec iov = {r, sizeof *r};
    struct msghdr m = {0};
    m.msg_iov = &iov;
    m.msg_iovlen = 1;
    m.msg_control = cm.buf;
    m.msg_controllen = sizeof cm.buf;
    ssize_t n;
    do
        n = recvmsg(ctl, &m, MSG_CMSG_CLOEXEC | MSG_WAITALL);
    while (n < 0 && errno == EINTR);
    if (n <= 0 || (n < (ssize_t)sizeof *r && recv_all(ctl, (char *)r + n, sizeof *r - (size_t)n) < 0)) {
        errno = ENODEV;
        return -1;
    }
    int got = 0;
    for (struct cmsghdr *c = CMSG_FIRSTHDR(&m); c; c = CMSG_NXTHDR(&m, c)) {
        if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_RIGHTS) {
            int k = (int)((c->cmsg_len - CMSG_LEN(0)) / sizeof(int));
            int *p = (int *)CMSG_DATA(c);
            for (int i = 0; i < k; i++) {
                if (fds && got < 2)
                    fds[got++] = p[i];
                else {
                    resolve_close();
                    real_close(p[i]);
                }
            }
        }
    }
    if (nfds)
        *nfds = got;
    uint32_t keep = r->len < cap ? r->len : cap;
    if (keep && recv_all(ctl, out, keep) < 0) {
        errno = ENODEV;
        return -1;
    }
    for (uint32_t left = r->len - keep; left > 0;) {
        char sink[4096];
        uint32_t k = left < sizeof sink ? left : sizeof sink;
        if (recv_all(ctl, sink, k) < 0) {
            errno = ENODEV;
            return -1;
        }
        left -= k;
    }
    return 0;
}

static int call(struct handle *h, const struct req *q, const void *payload, void *out, uint32_t cap,
                struct rsp *r, int *fds, int *nfds) {
    pthread_mutex_lock(&h->lock);
    int rc = xfer(h->ctl, q, payload, out, cap, r, fds, nfds);
    pthread_mutex_unlock(&h->lock);
    if (rc < 0) {
        r->result = -1;
        r->err = ENODEV;
    }
    return rc;
}

static int is_blocking(int fd) {
    resolve_fcntl();
    int fl = real_fcntl(fd, F_GETFL);
    return fl >= 0 && !(fl & O_NONBLOCK);
}

/* Wait until fd is readable (a blocking call's condition may hold); -1 with EINTR on a signal. */
static int wait_readable(int fd) {
    struct pollfd p = {fd, POLLIN, 0};
    resolve_poll();
    return real_poll(&p, 1, -1) < 0 ? -1 : 0;
}

/* -------------------------------------------------------------------------------------------- open */
static int emu_open(int index, const char *path, int flags) {
    int s = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (s < 0)
        return -1;
    struct sockaddr_un addr = {.sun_family = AF_UNIX};
    strcpy(addr.sun_path, sock_path);
    if (connect(s, (struct sockaddr *)&addr, sizeof addr) < 0) {
        resolve_close();
        real_close(s);
        trace("rollcam-preload: cannot reach the device server at %s\n", sock_path);
        errno = ENODEV;
        return -1;
    }
    struct req q = {OP_OPEN, (uint32_t)strlen(path), (uint64_t)(unsigned)flags, 0, 0};
    struct rsp r;
    int fds[2] = {-1, -1}, nfds = 0;
    if (xfer(s, &q, path, NULL, 0, &r, fds, &nfds) < 0 || r.err || nfds != 2) {
        int err = r.err ? r.err : ENODEV;
        resolve_close();
        real_close(s);
        for (int i = 0; i < nfds; i++)
            real_close(fds[i]);
        errno = err;
        return -1;
    }
    if (fds[0] >= MAX_FD) {
        resolve_close();
        real_close(s);
        real_close(fds[0]);
        real_close(fds[1]);
        errno = EMFILE;
        return -1;
    }
    resolve_fcntl();
    if (!(flags & O_CLOEXEC))
        real_fcntl(fds[0], F_SETFD, 0);
    if (flags & O_NONBLOCK)
        real_fcntl(fds[0], F_SETFL, O_NONBLOCK);
    struct handle *h = calloc(1, sizeof *h);
    h->ctl = s;
    h->readyfd = fds[0];
    h->evfd = fds[1];
    h->minor = minor_of(index);
    h->pid = getpid();
    pthread_mutex_init(&h->lock, NULL);
    attach(fds[0], h);
    trace("rollcam-preload: open(%s) = %d\n", path, fds[0]);
    return fds[0];
}

static mode_t open_mode(int flags, va_list ap) {
    return (flags & (O_CREAT | __O_TMPFILE)) ? va_arg(ap, mode_t) : 0;
}

#define OPEN_BODY(realcall) \
    int index = device_index(path); \
    if (index >= 0) \
        return emu_open(index, path, flags); \
    REDIRECT(path); \
    return realcall;

EXPORT int open(const char *path, int flags, ...) {
    va_list ap;
    va_start(ap, flags);
    mode_t mode = open_mode(flags, ap);
    va_end(ap);
    resolve_open();
    OPEN_BODY(real_open(path, flags, mode))
}

EXPORT int open64(const char *path, int flags, ...) {
    va_list ap;
    va_start(ap, flags);
    mode_t mode = open_mode(flags, ap);
    va_end(ap);
    resolve_open64();
    OPEN_BODY(real_open64(path, flags, mode))
}

EXPORT int openat(int dirfd, const char *path, int flags, ...) {
    va_list ap;
    va_start(ap, flags);
    mode_t mode = open_mode(flags, ap);
    va_end(ap);
    resolve_openat();
    OPEN_BODY(real_openat(dirfd, path, flags, mode))
}

EXPORT int openat64(int dirfd, const char *path, int flags, ...) {
    va_list ap;
    va_start(ap, flags);
    mode_t mode = open_mode(flags, ap);
    va_end(ap);
    resolve_openat64();
    OPEN_BODY(real_openat64(dirfd, path, flags, mode))
}

EXPORT int __open_2(const char *path, int flags) {
    resolve___open_2();
    OPEN_BODY(real___open_2(path, flags))
}

EXPORT int __open64_2(const char *path, int flags) {
    resolve___open64_2();
    OPEN_BODY(real___open64_2(path, flags))
}

EXPORT int __openat_2(int dirfd, const char *path, int flags) {
    resolve___openat_2();
    OPEN_BODY(real___openat_2(dirfd, path, flags))
}

EXPORT int __openat64_2(int dirfd, const char *path, int flags) {
    resolve___openat64_2();
    OPEN_BODY(real___openat64_2(dirfd, path, flags))
}

EXPORT int close(int fd) {
    resolve_close();
    struct handle *h = lookup(fd);
    if (!h)
        return real_close(fd);
    pthread_mutex_lock(&table_lock);
    int ok = __atomic_load_n(&table[fd], __ATOMIC_ACQUIRE) == h;
    pthread_mutex_unlock(&table_lock);
    if (ok)
        detach(fd);
    trace("rollcam-preload: close(%d)\n", fd);
    return real_close(fd);
}

/* ------------------------------------------------------------------------------------------- ioctl */
static int emu_ioctl(int fd, struct handle *h, unsigned long request, void *arg) {
    /* Requests the VFS answers for every file before any driver sees them. */
    if (request == FIONBIO || request == FIOCLEX || request == FIONCLEX || request == FIOASYNC) {
        resolve_ioctl();
        return real_ioctl(fd, request, arg);
    }
    uint32_t size = _IOC_SIZE(request), dir = _IOC_DIR(request);
    if (dir == _IOC_NONE)
        size = 0;
    if (size && !arg) {
        errno = EFAULT;
        return -1;
    }
    int ext = request == VIDIOC_G_EXT_CTRLS || request == VIDIOC_S_EXT_CTRLS || request == VIDIOC_TRY_EXT_CTRLS;
    uint32_t nctrl = 0, total = size;
    char small[512], *buf = small;
    if (ext) {
        struct v4l2_ext_controls *c = arg;
        nctrl = c->count <= MAX_EXT_CTRLS && c->controls ? c->count : 0;
        total += nctrl * (uint32_t)sizeof(struct v4l2_ext_control);
    }
    if (total > sizeof small && !(buf = malloc(total))) {
        errno = ENOMEM;
        return -1;
    }
    if (size)
        memcpy(buf, arg, size);
    if (nctrl)
        memcpy(buf + size, ((struct v4l2_ext_controls *)arg)->controls, nctrl * sizeof(struct v4l2_ext_control));
    struct req q = {OP_IOCTL, total, request, 0, 0};
    struct rsp r;
    int fds[2], nfds = 0;
    for (;;) {
        call(h, &q, buf, buf, total, &r, fds, &nfds);
        int wait_ev = request == VIDIOC_DQEVENT && r.err == ENOENT;
        if (!((request == VIDIOC_DQBUF && r.err == EAGAIN) || wait_ev) || !is_blocking(fd))
            break;
        if (wait_readable(wait_ev ? h->evfd : fd) < 0) {
            r.err = errno;
            break;
        }
    }
    if (r.len) {
        uint32_t back = r.len < size ? r.len : size;
        if (dir & _IOC_READ || ext)
            memcpy(arg, buf, back);
        if (nctrl && r.len >= total)
            memcpy(((struct v4l2_ext_controls *)arg)->controls, buf + size,
                   nctrl * sizeof(struct v4l2_ext_control));
    }
    if (buf != small)
        free(buf);
    if (nfds && request == VIDIOC_EXPBUF && !r.err)
        ((struct v4l2_exportbuffer *)arg)->fd = fds[0];
    else
        for (int i = 0; i < nfds; i++)
            real_close(fds[i]);
    if (r.err) {
        errno = r.err;
        return -1;
    }
    return (int)r.result;
}

EXPORT int ioctl(int fd, unsigned long request, ...) {
    va_list ap;
    va_start(ap, request);
    void *arg = va_arg(ap, void *);
    va_end(ap);
    struct handle *h = lookup(fd);
    if (h)
        return emu_ioctl(fd, h, request, arg);
    resolve_ioctl();
    return real_ioctl(fd, request, arg);
}

/* -------------------------------------------------------------------------------------------- mmap */
static void *emu_mmap(struct handle *h, void *addr, size_t len, int prot, int flags, off_t off) {
    struct req q = {OP_MMAP, 0, (uint64_t)off, len, (uint64_t)(unsigned)prot | ((uint64_t)(unsigned)flags << 32)};
    struct rsp r;
    int fds[2], nfds = 0;
    call(h, &q, NULL, NULL, 0, &r, fds, &nfds);
    if (r.err || nfds != 1) {
        for (int i = 0; i < nfds; i++)
            real_close(fds[i]);
        errno = r.err ? r.err : EINVAL;
        return MAP_FAILED;
    }
    resolve_mmap();
    void *p = real_mmap(addr, len, prot, flags, fds[0], (off_t)r.result);
    int err = errno;
    real_close(fds[0]);
    errno = err;
    return p;
}

EXPORT void *mmap(void *addr, size_t len, int prot, int flags, int fd, off_t off) {
    struct handle *h = lookup(fd);
    if (h)
        return emu_mmap(h, addr, len, prot, flags, off);
    resolve_mmap();
    return real_mmap(addr, len, prot, flags, fd, off);
}

EXPORT void *mmap64(void *addr, size_t len, int prot, int flags, int fd, off64_t off) {
    struct handle *h = lookup(fd);
    if (h)
        return emu_mmap(h, addr, len, prot, flags, (off_t)off);
    resolve_mmap64();
    return real_mmap64(addr, len, prot, flags, fd, off);
}

/* ---------------------------------------------------------------------------------------- read/write */
static ssize_t emu_read(int fd, struct handle *h, void *buf, size_t count) {
    struct req q = {OP_READ, 0, count, 0, 0};
    struct rsp r;
    for (;;) {
        call(h, &q, NULL, buf, count > UINT32_MAX ? UINT32_MAX : (uint32_t)count, &r, NULL, NULL);
        if (r.err != EAGAIN || !is_blocking(fd))
            break;
        if (wait_readable(fd) < 0)
            return -1;
    }
    if (r.err) {
        errno = r.err;
        return -1;
    }
    return (ssize_t)r.result;
}

EXPORT ssize_t read(int fd, void *buf, size_t count) {
    struct handle *h = lookup(fd);
    if (h)
        return emu_read(fd, h, buf, count);
    resolve_read();
    return real_read(fd, buf, count);
}

EXPORT ssize_t __read_chk(int fd, void *buf, size_t count, size_t buflen) {
    struct handle *h = lookup(fd);
    if (h)
        return emu_read(fd, h, buf, count < buflen ? count : buflen);
    resolve___read_chk();
    return real___read_chk(fd, buf, count, buflen);
}

EXPORT ssize_t write(int fd, const void *buf, size_t count) {
    if (lookup(fd)) {
        errno = EINVAL; /* a capture device has no write() */
        return -1;
    }
    resolve_write();
    return real_write(fd, buf, count);
}

/* -------------------------------------------------------------------------------------------- poll */
static short query_mask(struct handle *h, short events) {
    struct req q = {OP_POLL, 0, (uint64_t)(unsigned short)events, 1, 0};
    struct rsp r;
    if (call(h, &q, NULL, NULL, 0, &r, NULL, NULL) < 0)
        return POLLERR | POLLHUP;
    return r.err ? POLLERR : (short)r.result;
}

static long long now_ns(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

/* poll() with V4L2 masks for emulated fds: ask the server; if nothing is ready, wait on the eventfds (and
 * the other fds) until the deadline, then ask again. timeout_ns < 0: forever. */
static int emu_poll(struct pollfd *fds, nfds_t n, long long timeout_ns, const sigset_t *sigmask) {
    resolve_ppoll();
    struct pollfd small[32], *tmp = n * 2 <= 32 ? small : malloc(n * 2 * sizeof *tmp);
    if (!tmp) {
        errno = ENOMEM;
        return -1;
    }
    long long deadline = timeout_ns < 0 ? -1 : now_ns() + timeout_ns;
    int result;
    for (;;) {
        int ready = 0;
        nfds_t k = 0;
        for (nfds_t i = 0; i < n; i++) {
            struct handle *h = lookup(fds[i].fd);
            if (!h) {
                tmp[k++] = (struct pollfd){fds[i].fd, fds[i].events, 0};
                continue;
            }
            fds[i].revents = (short)(query_mask(h, fds[i].events) & (fds[i].events | POLLERR | POLLHUP));
            ready += fds[i].revents != 0;
            tmp[k++] = (struct pollfd){fds[i].events & (POLLIN | POLLRDNORM) ? fds[i].fd : -1, POLLIN, 0};
            tmp[k++] = (struct pollfd){fds[i].events & POLLPRI ? h->evfd : -1, POLLIN, 0};
        }
        struct timespec ts, *tsp = NULL;
        long long left = deadline < 0 ? -1 : deadline - now_ns();
        if (ready || (deadline >= 0 && left < 0))
            left = 0;
        if (left >= 0) {
            ts.tv_sec = left / 1000000000LL;
            ts.tv_nsec = left % 1000000000LL;
            tsp = &ts;
        }
        int r = real_ppoll(tmp, k, tsp, sigmask);
        if (r < 0) {
            result = -1;
            break;
        }
        int others = 0;
        k = 0;
        for (nfds_t i = 0; i < n; i++) {
            if (lookup(fds[i].fd)) {
                k += 2;
                continue;
            }
            fds[i].revents = tmp[k++].revents;
            others += fds[i].revents != 0;
        }
        if (ready || others || r == 0) {
            result = ready + others;
            break;
        }
    }
    if (tmp != small)
        free(tmp);
    return result;
}

static int any_emulated(const struct pollfd *fds, nfds_t n) {
    for (nfds_t i = 0; i < n; i++)
        if (lookup(fds[i].fd))
            return 1;
    return 0;
}

EXPORT int poll(struct pollfd *fds, nfds_t n, int timeout) {
    if (!any_emulated(fds, n)) {
        resolve_poll();
        return real_poll(fds, n, timeout);
    }
    return emu_poll(fds, n, timeout < 0 ? -1 : (long long)timeout * 1000000LL, NULL);
}

EXPORT int __poll_chk(struct pollfd *fds, nfds_t n, int timeout, size_t len) {
    (void)len;
    return poll(fds, n, timeout);
}

EXPORT int ppoll(struct pollfd *fds, nfds_t n, const struct timespec *t, const sigset_t *sigmask) {
    if (!any_emulated(fds, n)) {
        resolve_ppoll();
        return real_ppoll(fds, n, t, sigmask);
    }
    return emu_poll(fds, n, t ? (long long)t->tv_sec * 1000000000LL + t->tv_nsec : -1, sigmask);
}

/* select/pselect through emu_poll when an emulated fd is in a set (the kernel's POLLIN/OUT/EX sets). */
static int emu_select(int nfds, fd_set *rd, fd_set *wr, fd_set *ex, long long timeout_ns, const sigset_t *mask) {
    struct pollfd *p = calloc((size_t)(nfds > 0 ? nfds : 1), sizeof *p);
    if (!p) {
        errno = ENOMEM;
        return -1;
    }
    nfds_t n = 0;
    for (int fd = 0; fd < nfds; fd++) {
        short ev = (short)((rd && FD_ISSET(fd, rd) ? POLLIN : 0) | (wr && FD_ISSET(fd, wr) ? POLLOUT : 0) |
                           (ex && FD_ISSET(fd, ex) ? POLLPRI : 0));
        if (ev)
            p[n++] = (struct pollfd){fd, ev, 0};
    }
    int r = emu_poll(p, n, timeout_ns, mask);
    if (r >= 0) {
        r = 0;
        if (rd) FD_ZERO(rd);
        if (wr) FD_ZERO(wr);
        if (ex) FD_ZERO(ex);
        for (nfds_t i = 0; i < n; i++) {
            short re = p[i].revents;
            if (re & POLLNVAL) {
                free(p);
                errno = EBADF;
                return -1;
            }
            int hit = 0;
            if (rd && (p[i].events & POLLIN) && (re & (POLLIN | POLLRDNORM | POLLHUP | POLLERR)))
                FD_SET(p[i].fd, rd), hit++;
            if (wr && (p[i].events & POLLOUT) && (re & (POLLOUT | POLLWRNORM | POLLERR)))
                FD_SET(p[i].fd, wr), hit++;
            if (ex && (p[i].events & POLLPRI) && (re & POLLPRI))
                FD_SET(p[i].fd, ex), hit++;
            r += hit;
        }
    }
    free(p);
    return r;
}

static int select_has_emulated(int nfds, fd_set *rd, fd_set *wr, fd_set *ex) {
    for (int fd = 0; fd < nfds && fd < FD_SETSIZE; fd++)
        if (lookup(fd) && ((rd && FD_ISSET(fd, rd)) || (wr && FD_ISSET(fd, wr)) || (ex && FD_ISSET(fd, ex))))
            return 1;
    return 0;
}

EXPORT int select(int nfds, fd_set *rd, fd_set *wr, fd_set *ex, struct timeval *tv) {
    if (!select_has_emulated(nfds, rd, wr, ex)) {
        resolve_select();
        return real_select(nfds, rd, wr, ex, tv);
    }
    long long t = tv ? (long long)tv->tv_sec * 1000000000LL + (long long)tv->tv_usec * 1000LL : -1;
    long long start = now_ns();
    int r = emu_select(nfds, rd, wr, ex, t, NULL);
    if (tv) { /* Linux leaves the time not slept in the timeout */
        long long left = t - (now_ns() - start);
        if (left < 0)
            left = 0;
        tv->tv_sec = left / 1000000000LL;
        tv->tv_usec = (left % 1000000000LL) / 1000;
    }
    return r;
}

EXPORT int pselect(int nfds, fd_set *rd, fd_set *wr, fd_set *ex, const struct timespec *t, const sigset_t *mask) {
    if (!select_has_emulated(nfds, rd, wr, ex)) {
        resolve_pselect();
        return real_pselect(nfds, rd, wr, ex, t, mask);
    }
    return emu_select(nfds, rd, wr, ex, t ? (long long)t->tv_sec * 1000000000LL + t->tv_nsec : -1, mask);
}

/* --------------------------------------------------------------------------------------------- dup */
static int dup_result(int oldfd, int newfd) {
    struct handle *h = lookup(oldfd);
    if (newfd >= 0 && newfd != oldfd) {
        if (lookup(newfd))
            detach(newfd); /* dup2 onto an emulated fd closed it */
        if (h && newfd < MAX_FD)
            attach(newfd, h);
    }
    return newfd;
}

EXPORT int dup(int fd) {
    resolve_dup();
    return dup_result(fd, real_dup(fd));
}

EXPORT int dup2(int fd, int fd2) {
    resolve_dup2();
    return dup_result(fd, real_dup2(fd, fd2));
}

EXPORT int dup3(int fd, int fd2, int flags) {
    resolve_dup3();
    return dup_result(fd, real_dup3(fd, fd2, flags));
}

static int fcntl_common(int (*real)(int, int, ...), int fd, int cmd, void *arg) {
    int r = real(fd, cmd, arg);
    if ((cmd == F_DUPFD || cmd == F_DUPFD_CLOEXEC) && r >= 0 && lookup(fd))
        dup_result(fd, r);
    return r;
}

EXPORT int fcntl(int fd, int cmd, ...) {
    va_list ap;
    va_start(ap, cmd);
    void *arg = va_arg(ap, void *);
    va_end(ap);
    resolve_fcntl();
    return fcntl_common(real_fcntl, fd, cmd, arg);
}

EXPORT int fcntl64(int fd, int cmd, ...) {
    va_list ap;
    va_start(ap, cmd);
    void *arg = va_arg(ap, void *);
    va_end(ap);
    resolve_fcntl64();
    return fcntl_common(real_fcntl64 ? real_fcntl64 : (resolve_fcntl(), real_fcntl), fd, cmd, arg);
}

/* -------------------------------------------------------------------------------------------- stat */
static void fill_stat(struct stat *st, int minor) {
    memset(st, 0, sizeof *st);
    st->st_dev = makedev(0, 5);
    st->st_ino = 0x726f6c00u + (unsigned)minor;
    st->st_mode = S_IFCHR | 0666;
    st->st_nlink = 1;
    st->st_uid = getuid();
    st->st_gid = getgid();
    st->st_rdev = makedev(VIDEO_MAJOR, minor);
    st->st_blksize = 4096;
}

static int path_minor(const char *path) {
    int i = device_index(path);
    return i < 0 ? -1 : minor_of(i);
}

#define STAT_PATH(path, st, realcall) \
    int m = path_minor(path); \
    if (m >= 0) { fill_stat((struct stat *)(st), m); return 0; } \
    REDIRECT(path); \
    return realcall;

#define STAT_FD(fd, st, realcall) \
    struct handle *h = lookup(fd); \
    if (h) { fill_stat((struct stat *)(st), h->minor); return 0; } \
    return realcall;

EXPORT int stat(const char *p, struct stat *st) { resolve_stat(); STAT_PATH(p, st, real_stat(p, st)) }
EXPORT int stat64(const char *p, struct stat64 *st) { resolve_stat64(); STAT_PATH(p, st, real_stat64(p, st)) }
EXPORT int lstat(const char *p, struct stat *st) { resolve_lstat(); STAT_PATH(p, st, real_lstat(p, st)) }
EXPORT int lstat64(const char *p, struct stat64 *st) { resolve_lstat64(); STAT_PATH(p, st, real_lstat64(p, st)) }
EXPORT int fstat(int fd, struct stat *st) { resolve_fstat(); STAT_FD(fd, st, real_fstat(fd, st)) }
EXPORT int fstat64(int fd, struct stat64 *st) { resolve_fstat64(); STAT_FD(fd, st, real_fstat64(fd, st)) }

EXPORT int fstatat(int dirfd, const char *p, struct stat *st, int flags) {
    resolve_fstatat();
    if (p && !*p && (flags & AT_EMPTY_PATH)) {
        STAT_FD(dirfd, st, real_fstatat(dirfd, p, st, flags))
    }
    STAT_PATH(p, st, real_fstatat(dirfd, p, st, flags))
}

EXPORT int fstatat64(int dirfd, const char *p, struct stat64 *st, int flags) {
    resolve_fstatat64();
    if (p && !*p && (flags & AT_EMPTY_PATH)) {
        STAT_FD(dirfd, st, real_fstatat64(dirfd, p, st, flags))
    }
    STAT_PATH(p, st, real_fstatat64(dirfd, p, st, flags))
}

/* The pre-2.33 glibc entry points older binaries call; when libc lacks them, the plain call does. */
EXPORT int __xstat(int ver, const char *p, struct stat *st) {
    resolve___xstat();
    resolve_stat();
    STAT_PATH(p, st, real___xstat ? real___xstat(ver, p, st) : real_stat(p, st))
}
EXPORT int __xstat64(int ver, const char *p, struct stat64 *st) {
    resolve___xstat64();
    resolve_stat64();
    STAT_PATH(p, st, real___xstat64 ? real___xstat64(ver, p, st) : real_stat64(p, st))
}
EXPORT int __lxstat(int ver, const char *p, struct stat *st) {
    resolve___lxstat();
    resolve_lstat();
    STAT_PATH(p, st, real___lxstat ? real___lxstat(ver, p, st) : real_lstat(p, st))
}
EXPORT int __lxstat64(int ver, const char *p, struct stat64 *st) {
    resolve___lxstat64();
    resolve_lstat64();
    STAT_PATH(p, st, real___lxstat64 ? real___lxstat64(ver, p, st) : real_lstat64(p, st))
}
EXPORT int __fxstat(int ver, int fd, struct stat *st) {
    resolve___fxstat();
    resolve_fstat();
    STAT_FD(fd, st, real___fxstat ? real___fxstat(ver, fd, st) : real_fstat(fd, st))
}
EXPORT int __fxstat64(int ver, int fd, struct stat64 *st) {
    resolve___fxstat64();
    resolve_fstat64();
    STAT_FD(fd, st, real___fxstat64 ? real___fxstat64(ver, fd, st) : real_fstat64(fd, st))
}
EXPORT int __fxstatat(int ver, int dirfd, const char *p, struct stat *st, int flags) {
    resolve___fxstatat();
    resolve_fstatat();
    STAT_PATH(p, st, real___fxstatat ? real___fxstatat(ver, dirfd, p, st, flags) : real_fstatat(dirfd, p, st, flags))
}
EXPORT int __fxstatat64(int ver, int dirfd, const char *p, struct stat64 *st, int flags) {
    resolve___fxstatat64();
    resolve_fstatat64();
    STAT_PATH(p, st, real___fxstatat64 ? real___fxstatat64(ver, dirfd, p, st, flags)
                                       : real_fstatat64(dirfd, p, st, flags))
}

EXPORT int statx(int dirfd, const char *p, int flags, unsigned int mask, struct statx *stx) {
    resolve_statx();
    int m = -1;
    if (p && !*p && (flags & AT_EMPTY_PATH)) {
        struct handle *h = lookup(dirfd);
        m = h ? h->minor : -1;
    } else {
        m = path_minor(p);
    }
    if (m < 0) {
        REDIRECT(p);
        return real_statx(dirfd, p, flags, mask, stx);
    }
    memset(stx, 0, sizeof *stx);
    stx->stx_mask = STATX_BASIC_STATS;
    stx->stx_blksize = 4096;
    stx->stx_nlink = 1;
    stx->stx_uid = getuid();
    stx->stx_gid = getgid();
    stx->stx_mode = S_IFCHR | 0666;
    stx->stx_ino = 0x726f6c00u + (unsigned)m;
    stx->stx_rdev_major = VIDEO_MAJOR;
    stx->stx_rdev_minor = (unsigned)m;
    stx->stx_dev_minor = 5;
    return 0;
}

EXPORT int access(const char *p, int mode) {
    resolve_access();
    if (device_index(p) >= 0)
        return 0;
    REDIRECT(p);
    return real_access(p, mode);
}

EXPORT int faccessat(int dirfd, const char *p, int mode, int flags) {
    resolve_faccessat();
    if (device_index(p) >= 0)
        return 0;
    REDIRECT(p);
    return real_faccessat(dirfd, p, mode, flags);
}

EXPORT int eaccess(const char *p, int mode) {
    resolve_eaccess();
    if (device_index(p) >= 0)
        return 0;
    REDIRECT(p);
    return real_eaccess(p, mode);
}

EXPORT int euidaccess(const char *p, int mode) {
    resolve_euidaccess();
    if (device_index(p) >= 0)
        return 0;
    REDIRECT(p);
    return real_euidaccess(p, mode);
}

/* ---------------------------------------------------------------------------------------- directories */
/* A listing of /dev ends with the emulated nodes it lacks (v4l2-ctl --list-devices, device scanners). */
struct dir_state { DIR *dir; int next; int seen[MAX_DEVICES]; struct dirent ent; struct dirent64 ent64; };
static struct dir_state dirs[8];
static pthread_mutex_t dirs_lock = PTHREAD_MUTEX_INITIALIZER;

EXPORT DIR *opendir(const char *name) {
    resolve_opendir();
    const char *orig = name;
    REDIRECT(name);
    DIR *d = real_opendir(name);
    name = orig;
    if (!d || !n_devices || !name || (strcmp(name, "/dev") != 0 && strcmp(name, "/dev/") != 0))
        return d;
    pthread_mutex_lock(&dirs_lock);
    for (int i = 0; i < 8; i++) {
        if (!dirs[i].dir) {
            memset(&dirs[i], 0, sizeof dirs[i]);
            dirs[i].dir = d;
            break;
        }
    }
    pthread_mutex_unlock(&dirs_lock);
    return d;
}

static struct dir_state *dir_of(DIR *d) {
    for (int i = 0; i < 8; i++)
        if (dirs[i].dir == d)
            return &dirs[i];
    return NULL;
}

static const char *next_missing(struct dir_state *s, const char *real_name) {
    if (real_name) { /* a real entry: note a device node that exists */
        for (int i = 0; i < n_devices; i++)
            if (strcmp(devices[i] + 5, real_name) == 0)
                s->seen[i] = 1;
        return NULL;
    }
    while (s->next < n_devices) {
        int i = s->next++;
        if (!s->seen[i] && strncmp(devices[i], "/dev/", 5) == 0 && !strchr(devices[i] + 5, '/'))
            return devices[i] + 5;
    }
    return NULL;
}

EXPORT struct dirent *readdir(DIR *d) {
    resolve_readdir();
    struct dirent *e = real_readdir(d);
    pthread_mutex_lock(&dirs_lock);
    struct dir_state *s = dir_of(d);
    if (s) {
        const char *name = next_missing(s, e ? e->d_name : NULL);
        if (!e && name) {
            memset(&s->ent, 0, sizeof s->ent);
            s->ent.d_type = DT_CHR;
            s->ent.d_ino = 1;
            snprintf(s->ent.d_name, sizeof s->ent.d_name, "%s", name);
            e = &s->ent;
        }
    }
    pthread_mutex_unlock(&dirs_lock);
    return e;
}

EXPORT struct dirent64 *readdir64(DIR *d) {
    resolve_readdir64();
    struct dirent64 *e = real_readdir64(d);
    pthread_mutex_lock(&dirs_lock);
    struct dir_state *s = dir_of(d);
    if (s) {
        const char *name = next_missing(s, e ? e->d_name : NULL);
        if (!e && name) {
            memset(&s->ent64, 0, sizeof s->ent64);
            s->ent64.d_type = DT_CHR;
            s->ent64.d_ino = 1;
            snprintf(s->ent64.d_name, sizeof s->ent64.d_name, "%s", name);
            e = &s->ent64;
        }
    }
    pthread_mutex_unlock(&dirs_lock);
    return e;
}

EXPORT int closedir(DIR *d) {
    resolve_closedir();
    pthread_mutex_lock(&dirs_lock);
    struct dir_state *s = dir_of(d);
    if (s)
        s->dir = NULL;
    pthread_mutex_unlock(&dirs_lock);
    return real_closedir(d);
}

EXPORT FILE *fopen(const char *p, const char *mode) {
    resolve_fopen();
    REDIRECT(p);
    return real_fopen(p, mode);
}

EXPORT FILE *fopen64(const char *p, const char *mode) {
    resolve_fopen64();
    REDIRECT(p);
    return real_fopen64(p, mode);
}

EXPORT ssize_t readlink(const char *p, char *buf, size_t len) {
    resolve_readlink();
    REDIRECT(p);
    return real_readlink(p, buf, len);
}

/* --------------------------------------------------------------------------------------------- syscall */
/* libv4l2 (v4l2-ctl -w, GST_V4L2_USE_LIBV4L2=1) calls the kernel through syscall(); route its calls too. */
EXPORT long syscall(long number, ...) {
    va_list ap;
    va_start(ap, number);
    long a[6];
    for (int i = 0; i < 6; i++)
        a[i] = va_arg(ap, long);
    va_end(ap);
    switch (number) {
    case SYS_ioctl:
        if (lookup((int)a[0]))
            return ioctl((int)a[0], (unsigned long)a[1], (void *)a[2]);
        break;
    case SYS_openat:
        if (device_index((const char *)a[1]) >= 0)
            return emu_open(device_index((const char *)a[1]), (const char *)a[1], (int)a[2]);
        break;
    case SYS_close:
        if (lookup((int)a[0]))
            return close((int)a[0]);
        break;
    case SYS_read:
        if (lookup((int)a[0]))
            return read((int)a[0], (void *)a[1], (size_t)a[2]);
        break;
    case SYS_mmap:
        if (lookup((int)a[4]))
            return (long)mmap((void *)a[0], (size_t)a[1], (int)a[2], (int)a[3], (int)a[4], (off_t)a[5]);
        break;
    default:
        break;
    }
    resolve_syscall();
    return real_syscall(number, a[0], a[1], a[2], a[3], a[4], a[5]);
}
