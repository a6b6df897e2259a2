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
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
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

#include "rollcam_wire.h"


#define EXPORT __attribute__((visibility("default")))
#define MAX_FD 65536
#define MAX_DEVICES 16
#define MAX_EXT_CTRLS 1024
#define VIDEO_MAJOR 81

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

/* One line to stderr through the real write (the program's own may be interposed or redirected). */
static void vsay(const char *fmt, va_list ap) {
    char buf[512];
    int n = vsnprintf(buf, sizeof buf, fmt, ap);
    resolve_write();
    if (n > 0)
        real_write(2, buf, (size_t)n < sizeof buf ? (size_t)n : sizeof buf - 1);
}

static void trace(const char *fmt, ...) {
    if (!debug)
        return;
    va_list ap;
    va_start(ap, fmt);
    vsay(fmt, ap);
    va_end(ap);
}

static void fork_prepare(void);
static void fork_parent(void);
static void fork_child(void);
static sigset_t all_signals;

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
    sigfillset(&all_signals);
    pthread_atfork(fork_prepare, fork_parent, fork_child);
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


/* ------------------------------------------------------------------------------------ program memory */
/*
 * The ioctl argument, the read() buffer and the poll/select sets are the program's memory: a bad pointer
 * there gets EFAULT, as the kernel's copy_from_user/copy_to_user give it, never a SIGSEGV in this library.
 * The copies are process_vm_readv/process_vm_writev on this process (one system call each, no signal handler
 * to install over the program's, safe in any thread, no shared state). Where a seccomp policy refuses those
 * calls (ENOSYS, EPERM), a pipe does the same job: write() reads the program's memory and read() writes it,
 * each failing with EFAULT on a bad address.
 */
static int vm_calls_refused;

static int pipe_copy(void *dst, const void *src, size_t n) {
    int p[2];
    if (pipe2(p, O_CLOEXEC) < 0)
        return -1;
    resolve_read();
    resolve_write();
    resolve_close();
    int rc = 0;
    for (size_t done = 0; done < n && rc == 0;) {
        size_t k = n - done < 4096 ? n - done : 4096; /* under the pipe's capacity: write never blocks */
        if (real_write(p[1], (const char *)src + done, k) != (ssize_t)k ||
            real_read(p[0], (char *)dst + done, k) != (ssize_t)k)
            rc = -1;
        done += k;
    }
    real_close(p[0]);
    real_close(p[1]);
    if (rc < 0)
        errno = EFAULT;
    return rc;
}

/* Copy n bytes between the program's memory (user) and the library's; -1 with EFAULT when user is bad. */
static int user_copy(void *dst, const void *src, size_t n, int to_user) {
    if (!n)
        return 0;
    if (!__atomic_load_n(&vm_calls_refused, __ATOMIC_RELAXED)) {
        struct iovec local = {to_user ? (void *)src : dst, n}, remote = {to_user ? dst : (void *)src, n};
        ssize_t r = to_user ? process_vm_writev(getpid(), &local, 1, &remote, 1, 0)
                            : process_vm_readv(getpid(), &local, 1, &remote, 1, 0);
        if (r == (ssize_t)n)
            return 0;
        if (r >= 0 || errno == EFAULT) {
            errno = EFAULT;
            return -1;
        }
        if (errno != ENOSYS && errno != EPERM)
            return -1;
        __atomic_store_n(&vm_calls_refused, 1, __ATOMIC_RELAXED);
    }
    return pipe_copy(dst, src, n);
}

#define copy_in(lib, user, n) user_copy((lib), (user), (n), 0)
#define copy_out(user, lib, n) user_copy((user), (lib), (n), 1)

/* ------------------------------------------------------------------------------------------ handles */
/*
 * A handle is one open file of a device as this process sees it: its connection to the server and the fds
 * the server handed over. Its lifetime is the kernel's struct file's: the table holds a reference for each
 * program fd (dup adds one), each call holds one for its length (get/put, as the kernel's fdget/fdput), and
 * whoever drops the last one sends OP_CLOSE. So a thread blocked in DQBUF keeps the handle alive through
 * another thread's close(), and two closes cannot free it twice. table_lock guards the table, the counts
 * and the list of live handles; h->lock makes each request and its answer on h->ctl one exchange.
 *
 * fork: the child shares each open file with its parent, as on Linux (its STREAMOFF stops the parent's
 * stream). Before the fork the parent opens a connection for the child to each of its files (OP_ATTACH);
 * the child uses that one and drops its copy of the parent's, so the two never interleave on one socket
 * and the file is released when the last process closes it. The locks are reset in the child.
 */
struct handle {
    int ctl;              /* this process's connection to the server */
    int waitfd;           /* the library's own dup of the ready pipe: waited on, whatever the program closes */
    int evfd;             /* readable while events are pending */
    int minor;
    int64_t file;         /* the server's id of the open file (OP_ATTACH) */
    int refs;             /* table slots + calls in flight (table_lock) */
    int slots;            /* table slots (table_lock) */
    int dead;             /* the connection broke: every call fails with ENODEV (lock) */
    int child_ctl;        /* fork: the child's connection, made before the fork (table_lock, held across it) */
    pthread_mutex_t lock;
    struct handle *next;  /* live handles (table_lock) */
};

static struct handle *table[MAX_FD];
static struct handle *live;
static pthread_mutex_t table_lock = PTHREAD_MUTEX_INITIALIZER;

/* Whether fd is emulated now (no reference taken: for the fast path of every libc call). */
static int emulated(int fd) {
    return fd >= 0 && fd < MAX_FD && __atomic_load_n(&table[fd], __ATOMIC_ACQUIRE) != NULL;
}

/* fd's handle with a reference held for the caller's call (put() it), or NULL. */
static struct handle *get(int fd) {
    if (!emulated(fd))
        return NULL;
    pthread_mutex_lock(&table_lock);
    struct handle *h = table[fd];
    if (h)
        h->refs++;
    pthread_mutex_unlock(&table_lock);
    return h;
}

static int call(struct handle *h, const struct rollcam_req *q, const void *payload, void *out, uint32_t cap,
                struct rollcam_rsp *r, int *fds, int *nfds);

/* The last reference is gone: the file is closed (released before the program's close() returns). */
static void release(struct handle *h) {
    struct rollcam_req q = {OP_CLOSE, 0, 0, 0, 0};
    struct rollcam_rsp r;
    call(h, &q, NULL, NULL, 0, &r, NULL, NULL);
    resolve_close();
    real_close(h->ctl);
    real_close(h->waitfd);
    real_close(h->evfd);
    pthread_mutex_destroy(&h->lock);
    free(h);
}

static void unlink_live(struct handle *h) {
    for (struct handle **p = &live; *p; p = &(*p)->next)
        if (*p == h) {
            __atomic_store_n(p, h->next, __ATOMIC_RELEASE);
            return;
        }
}

/* Whether any device is open in this process (the fast path of poll/select: no copy of their sets). */
static int any_live(void) {
    return __atomic_load_n(&live, __ATOMIC_ACQUIRE) != NULL;
}

/* Drop a reference from get() or from a table slot (NULL: nothing); errno is kept. */
static void put(struct handle *h) {
    if (!h)
        return;
    int err = errno;
    pthread_mutex_lock(&table_lock);
    int last = --h->refs == 0;
    if (last)
        unlink_live(h);
    pthread_mutex_unlock(&table_lock);
    if (last)
        release(h);
    errno = err;
}

/* fd now refers to h (NULL: to no emulated file); returns the handle the slot held, whose reference the
 * caller drops with put() (outside table_lock: it may be the last). */
static struct handle *set_slot(int fd, struct handle *h) {
    if (fd < 0 || fd >= MAX_FD)
        return NULL;
    pthread_mutex_lock(&table_lock);
    struct handle *old = table[fd];
    if (h) {
        if (!h->refs) { /* a new handle */
            h->next = live;
            __atomic_store_n(&live, h, __ATOMIC_RELEASE);
        }
        h->refs++;
        h->slots++;
    }
    if (old)
        old->slots--;
    __atomic_store_n(&table[fd], h, __ATOMIC_RELEASE);
    pthread_mutex_unlock(&table_lock);
    return old;
}

/* ------------------------------------------------------------------------------------------ transport */
static int send_all(int fd, const void *head, size_t head_len, const void *payload, size_t len) {
    struct iovec iov[2] = {{(void *)head, head_len}, {(void *)payload, len}};
    size_t total = head_len + len, sent = 0;
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
        m.msg_iovlen = (size_t)n;
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

/* One request and its answer on ctl. The answer's payload goes to out (up to cap bytes; the rest is read
 * and dropped); fds passed with it land in fds (up to ROLLCAM_WIRE_MAX_FDS, *nfds of them; others are
 * closed). Returns 0, or -1 when the connection broke (no fds are left open then). */
static int xfer(int ctl, const struct rollcam_req *q, const void *payload, void *out, uint32_t cap,
                struct rollcam_rsp *r, int *fds, int *nfds) {
    int got = 0;
    if (nfds)
        *nfds = 0;
    if (send_all(ctl, q, sizeof *q, payload, q->len) < 0)
        return -1;
    union { char buf[CMSG_SPACE(ROLLCAM_WIRE_MAX_FDS * sizeof(int))]; struct cmsghdr align; } cm;
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
    if (n > 0) {
        for (struct cmsghdr *c = CMSG_FIRSTHDR(&m); c; c = CMSG_NXTHDR(&m, c)) {
            if (c->cmsg_level != SOL_SOCKET || c->cmsg_type != SCM_RIGHTS)
                continue;
            int k = (int)((c->cmsg_len - CMSG_LEN(0)) / sizeof(int));
            for (int i = 0; i < k; i++) {
                int fd;
                memcpy(&fd, CMSG_DATA(c) + i * sizeof(int), sizeof fd);
                if (fds && got < ROLLCAM_WIRE_MAX_FDS)
                    fds[got++] = fd;
                else
                    real_close(fd);
            }
        }
    }
    int ok = n > 0 && (n == (ssize_t)sizeof *r || recv_all(ctl, (char *)r + n, sizeof *r - (size_t)n) == 0);
    uint32_t keep = ok ? (r->len < cap ? r->len : cap) : 0;
    ok = ok && (!keep || recv_all(ctl, out, keep) == 0);
    for (uint32_t left = ok ? r->len - keep : 0; ok && left > 0;) {
        char sink[4096];
        uint32_t k = left < sizeof sink ? left : (uint32_t)sizeof sink;
        ok = recv_all(ctl, sink, k) == 0;
        left -= k;
    }
    if (!ok) {
        for (int i = 0; i < got; i++)
            real_close(fds[i]);
        return -1;
    }
    if (nfds)
        *nfds = got;
    return 0;
}

/* A request on h's connection, one at a time, with the program's signals held off for its few microseconds
 * (the server answers at once): a handler that calls into the library, or longjmps out of it, never finds the
 * connection mid-exchange. A broken connection fails this and every later call with ENODEV. */
static int call(struct handle *h, const struct rollcam_req *q, const void *payload, void *out, uint32_t cap,
                struct rollcam_rsp *r, int *fds, int *nfds) {
    sigset_t old;
    pthread_sigmask(SIG_BLOCK, &all_signals, &old);
    pthread_mutex_lock(&h->lock);
    int rc = h->dead ? -1 : xfer(h->ctl, q, payload, out, cap, r, fds, nfds);
    if (rc < 0)
        h->dead = 1;
    pthread_mutex_unlock(&h->lock);
    pthread_sigmask(SIG_SETMASK, &old, NULL);
    if (rc < 0) {
        *r = (struct rollcam_rsp){-1, ENODEV, 0};
        if (nfds)
            *nfds = 0;
    }
    return rc;
}

static void say(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsay(fmt, ap);
    va_end(ap);
}

/* A new connection to the server, past the hello; -1 with ENODEV when there is none or it speaks another
 * wire format (said on stderr: that is a broken install, not a missing device). */
static int dial(void) {
    int s = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (s < 0)
        return -1;
    struct sockaddr_un addr = {.sun_family = AF_UNIX};
    memcpy(addr.sun_path, sock_path, sizeof addr.sun_path);
    struct rollcam_hello mine = {ROLLCAM_WIRE_MAGIC, ROLLCAM_WIRE_VERSION}, theirs = {0, 0};
    resolve_close();
    if (connect(s, (struct sockaddr *)&addr, sizeof addr) < 0 || send_all(s, &mine, sizeof mine, NULL, 0) < 0 ||
        recv_all(s, &theirs, sizeof theirs) < 0) {
        real_close(s);
        trace("rollcam-preload: cannot reach the device server at %s\n", sock_path);
        errno = ENODEV;
        return -1;
    }
    if (theirs.magic != mine.magic || theirs.version != mine.version) {
        say("rollcam-preload: the device server at %s speaks wire format %u (magic %#x), this library %u: "
            "reinstall rollcam so that both come from one build\n", sock_path, theirs.version, theirs.magic,
            mine.version);
        real_close(s);
        errno = ENODEV;
        return -1;
    }
    return s;
}

static int is_blocking(struct handle *h) {
    resolve_fcntl();
    int fl = real_fcntl(h->waitfd, F_GETFL); /* the program's fd shares this open file's O_NONBLOCK */
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
    int s = dial();
    if (s < 0)
        return -1;
    struct rollcam_req q = {OP_OPEN, (uint32_t)strlen(path), (uint64_t)(unsigned)flags, 0, 0};
    struct rollcam_rsp r;
    int fds[ROLLCAM_WIRE_MAX_FDS] = {-1, -1}, nfds = 0, err = ENODEV;
    struct handle *h = NULL;
    resolve_close();
    resolve_fcntl();
    if (xfer(s, &q, path, NULL, 0, &r, fds, &nfds) == 0) {
        err = r.err ? r.err : nfds != 2 ? ENODEV : fds[0] >= MAX_FD ? EMFILE : 0;
        if (!err && !(h = calloc(1, sizeof *h)))
            err = ENOMEM;
        if (!err && (h->waitfd = real_fcntl(fds[0], F_DUPFD_CLOEXEC, 0)) < 0)
            err = errno;
    }
    if (err) {
        real_close(s);
        for (int i = 0; i < nfds; i++)
            real_close(fds[i]);
        free(h);
        errno = err;
        return -1;
    }
    if (!(flags & O_CLOEXEC))
        real_fcntl(fds[0], F_SETFD, 0);
    if (flags & O_NONBLOCK)
        real_fcntl(fds[0], F_SETFL, O_NONBLOCK);
    h->ctl = s;
    h->evfd = fds[1];
    h->minor = minor_of(index);
    h->file = r.result;
    h->child_ctl = -1;
    pthread_mutex_init(&h->lock, NULL);
    put(set_slot(fds[0], h));
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

/* The slot goes before the fd number is freed (so a racing open() that gets the number finds it empty); the
 * slot's reference goes after, and with it the file when that was the last. */
EXPORT int close(int fd) {
    resolve_close();
    if (!emulated(fd))
        return real_close(fd);
    struct handle *h = set_slot(fd, NULL);
    int rc = real_close(fd);
    put(h);
    trace("rollcam-preload: close(%d)\n", fd);
    return rc;
}

/* ------------------------------------------------------------------------------------------- ioctl */
static int is_ext_ctrls(unsigned int request) {
    return request == VIDIOC_G_EXT_CTRLS || request == VIDIOC_S_EXT_CTRLS || request == VIDIOC_TRY_EXT_CTRLS;
}

/* An ioctl as video_usercopy makes it: the argument copied in (_IOC_WRITE) or zeroed, the request sent, the
 * answer copied out (_IOC_READ), EFAULT for memory the program cannot lend; a blocking DQBUF/DQEVENT waits on
 * the readiness pipes between tries. request is 32 bits, as the kernel compares it. */
static int emu_ioctl(int fd, struct handle *h, unsigned int request, void *arg) {
    if (request == FIONBIO || request == FIOCLEX || request == FIONCLEX || request == FIOASYNC) {
        resolve_ioctl();
        return real_ioctl(fd, request, arg); /* the VFS answers these for every file */
    }
    uint32_t dir = _IOC_DIR(request), size = dir == _IOC_NONE ? 0 : _IOC_SIZE(request), nctrl = 0;
    const uint32_t csize = (uint32_t)sizeof(struct v4l2_ext_control);
    struct v4l2_ext_controls head = {0};
    int ext = is_ext_ctrls(request) && size == sizeof head;
    if (ext) {
        if (copy_in(&head, arg, size) < 0)
            return -1;
        nctrl = head.count <= MAX_EXT_CTRLS && head.controls ? head.count : 0;
    }
    uint32_t total = size + nctrl * csize;
    char small[2 * 512], *in = small;
    if (2 * (size_t)total > sizeof small && !(in = malloc(2 * (size_t)total))) {
        errno = ENOMEM;
        return -1;
    }
    char *out = in + total; /* the answer lands apart from the request: a retried DQBUF resends the same */
    int rc = -1, err = EFAULT;
    if (size && (dir & _IOC_WRITE ? copy_in(in, arg, size) : (memset(in, 0, size), 0)) < 0)
        goto done;
    if (nctrl && copy_in(in + size, head.controls, nctrl * csize) < 0)
        goto done;
    struct rollcam_req q = {OP_IOCTL, total, request, 0, 0};
    struct rollcam_rsp r;
    int fds[ROLLCAM_WIRE_MAX_FDS], nfds = 0;
    for (;;) {
        call(h, &q, in, out, total, &r, fds, &nfds);
        int wait_ev = request == VIDIOC_DQEVENT && r.err == ENOENT;
        if (!((request == VIDIOC_DQBUF && r.err == EAGAIN) || wait_ev) || !is_blocking(h))
            break;
        if (wait_readable(wait_ev ? h->evfd : h->waitfd) < 0) {
            r.err = errno;
            break;
        }
    }
    int keep = -1; /* the fd EXPBUF gives the program */
    if (request == VIDIOC_EXPBUF && !r.err && nfds && r.len >= sizeof(struct v4l2_exportbuffer)) {
        keep = fds[0];
        memcpy(out + offsetof(struct v4l2_exportbuffer, fd), &keep, sizeof keep);
    }
    err = r.err;
    if (r.len) {
        uint32_t back = r.len < size ? r.len : size;
        if (((dir & _IOC_READ) || ext) && copy_out(arg, out, back) < 0)
            err = EFAULT;
        else if (nctrl && r.len >= total && copy_out(head.controls, out + size, nctrl * csize) < 0)
            err = EFAULT;
    }
    for (int i = 0; i < nfds; i++)
        if (fds[i] != keep || err)
            real_close(fds[i]);
    rc = err ? -1 : (int)r.result;
done:
    if (in != small)
        free(in);
    errno = err;
    return rc;
}

EXPORT int ioctl(int fd, unsigned long request, ...) {
    va_list ap;
    va_start(ap, request);
    void *arg = va_arg(ap, void *);
    va_end(ap);
    struct handle *h = get(fd);
    if (!h) {
        resolve_ioctl();
        return real_ioctl(fd, request, arg);
    }
    int rc = emu_ioctl(fd, h, (unsigned int)request, arg);
    put(h);
    return rc;
}

/* -------------------------------------------------------------------------------------------- mmap */
static void *emu_mmap(struct handle *h, void *addr, size_t len, int prot, int flags, off_t off) {
    struct rollcam_req q = {OP_MMAP, 0, (uint64_t)off, len,
                            (uint64_t)(unsigned)prot | ((uint64_t)(unsigned)flags << 32)};
    struct rollcam_rsp r;
    int fds[ROLLCAM_WIRE_MAX_FDS], nfds = 0;
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
    struct handle *h = get(fd);
    if (!h) {
        resolve_mmap();
        return real_mmap(addr, len, prot, flags, fd, off);
    }
    void *p = emu_mmap(h, addr, len, prot, flags, off);
    put(h);
    return p;
}

EXPORT void *mmap64(void *addr, size_t len, int prot, int flags, int fd, off64_t off) {
    struct handle *h = get(fd);
    if (!h) {
        resolve_mmap64();
        return real_mmap64(addr, len, prot, flags, fd, off);
    }
    void *p = emu_mmap(h, addr, len, prot, flags, (off_t)off);
    put(h);
    return p;
}

/* ---------------------------------------------------------------------------------------- read/write */
#define MAX_READ (64u << 20) /* one read() returns at most this much (more than any frame) */

static ssize_t emu_read(struct handle *h, void *buf, size_t count) {
    uint32_t cap = count < MAX_READ ? (uint32_t)count : MAX_READ;
    char *tmp = malloc(cap ? cap : 1);
    if (!tmp) {
        errno = ENOMEM;
        return -1;
    }
    struct rollcam_req q = {OP_READ, 0, cap, 0, 0};
    struct rollcam_rsp r;
    for (;;) {
        call(h, &q, NULL, tmp, cap, &r, NULL, NULL);
        if (r.err != EAGAIN || !is_blocking(h))
            break;
        if (wait_readable(h->waitfd) < 0) {
            r.err = errno;
            break;
        }
    }
    ssize_t n = r.err ? -1 : (ssize_t)(r.len < cap ? r.len : cap);
    if (n > 0 && copy_out(buf, tmp, (size_t)n) < 0)
        r.err = EFAULT, n = -1;
    free(tmp);
    if (r.err)
        errno = r.err;
    return n;
}

EXPORT ssize_t read(int fd, void *buf, size_t count) {
    struct handle *h = get(fd);
    if (!h) {
        resolve_read();
        return real_read(fd, buf, count);
    }
    ssize_t n = emu_read(h, buf, count);
    put(h);
    return n;
}

EXPORT ssize_t __read_chk(int fd, void *buf, size_t count, size_t buflen) {
    struct handle *h = get(fd);
    if (!h) {
        resolve___read_chk();
        return real___read_chk(fd, buf, count, buflen);
    }
    ssize_t n = emu_read(h, buf, count < buflen ? count : buflen);
    put(h);
    return n;
}

EXPORT ssize_t write(int fd, const void *buf, size_t count) {
    if (emulated(fd)) {
        errno = EINVAL; /* a capture device has no write() */
        return -1;
    }
    resolve_write();
    return real_write(fd, buf, count);
}

/* -------------------------------------------------------------------------------------------- poll */
static short query_mask(struct handle *h, short events) {
    struct rollcam_req q = {OP_POLL, 0, (uint64_t)(unsigned short)events, 1, 0};
    struct rollcam_rsp r;
    if (call(h, &q, NULL, NULL, 0, &r, NULL, NULL) < 0)
        return POLLERR | POLLHUP;
    return r.err ? POLLERR : (short)r.result;
}

static long long now_ns(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

/* poll() with V4L2 masks for emulated fds (hs[i]: fds[i]'s handle or NULL): ask the server; if nothing is
 * ready, wait on the readiness pipes (and the other fds) until the deadline, then ask again. timeout_ns < 0:
 * forever. fds is the library's copy. */
static int emu_poll(struct pollfd *fds, struct handle **hs, nfds_t n, long long timeout_ns, const sigset_t *mask) {
    resolve_ppoll();
    struct pollfd *tmp = malloc(2 * n * sizeof *tmp);
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
            struct handle *h = hs[i];
            if (!h) {
                tmp[k++] = (struct pollfd){fds[i].fd, fds[i].events, 0};
                continue;
            }
            fds[i].revents = (short)(query_mask(h, fds[i].events) & (fds[i].events | POLLERR | POLLHUP));
            ready += fds[i].revents != 0;
            tmp[k++] = (struct pollfd){fds[i].events & (POLLIN | POLLRDNORM) ? h->waitfd : -1, POLLIN, 0};
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
        int r = real_ppoll(tmp, k, tsp, mask);
        if (r < 0) {
            result = -1;
            break;
        }
        int others = 0;
        k = 0;
        for (nfds_t i = 0; i < n; i++) {
            if (hs[i]) {
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
    free(tmp);
    return result;
}

#define MAX_POLL_FDS 65536

/* poll on a copy of the program's array, with a reference to each emulated fd's handle for the wait;
 * 1: fds holds none (or is the program's bad memory), and the real call should answer instead. */
static int poll_copy(struct pollfd *fds, nfds_t n, long long timeout_ns, const sigset_t *mask, int *result) {
    if (!any_live() || n == 0 || n > MAX_POLL_FDS)
        return 1;
    struct pollfd *copy = malloc(n * sizeof *copy);
    struct handle **hs = calloc(n, sizeof *hs);
    int any = 0, err = 0;
    if (!copy || !hs)
        err = ENOMEM;
    else if (copy_in(copy, fds, n * sizeof *copy) < 0)
        err = -1; /* the real call gives the EFAULT */
    for (nfds_t i = 0; !err && i < n; i++)
        any |= (hs[i] = get(copy[i].fd)) != NULL;
    if (any) {
        *result = emu_poll(copy, hs, n, timeout_ns, mask);
        int e = errno;
        if (*result >= 0 && copy_out(fds, copy, n * sizeof *copy) < 0)
            *result = -1, e = EFAULT;
        for (nfds_t i = 0; i < n; i++)
            put(hs[i]);
        errno = e;
    } else if (err > 0) {
        *result = -1;
        errno = err;
    }
    free(copy);
    free(hs);
    return !any && err <= 0;
}

EXPORT int poll(struct pollfd *fds, nfds_t n, int timeout) {
    int r;
    if (poll_copy(fds, n, timeout < 0 ? -1 : (long long)timeout * 1000000LL, NULL, &r)) {
        resolve_poll();
        return real_poll(fds, n, timeout);
    }
    return r;
}

EXPORT int __poll_chk(struct pollfd *fds, nfds_t n, int timeout, size_t len) {
    (void)len;
    return poll(fds, n, timeout);
}

EXPORT int ppoll(struct pollfd *fds, nfds_t n, const struct timespec *t, const sigset_t *sigmask) {
    int r;
    struct timespec tc;
    int bad_t = t && copy_in(&tc, t, sizeof tc) < 0; /* the real call gives the EFAULT */
    if (bad_t || poll_copy(fds, n, t ? (long long)tc.tv_sec * 1000000000LL + tc.tv_nsec : -1, sigmask, &r)) {
        resolve_ppoll();
        return real_ppoll(fds, n, t, sigmask);
    }
    return r;
}

/* select/pselect through emu_poll when an emulated fd is in a set (the kernel's POLLIN/OUT/EX sets); the
 * sets are the library's copies. 1: none is emulated, the real call should answer. */
static int emu_select(int nfds, fd_set *rd, fd_set *wr, fd_set *ex, long long timeout_ns, const sigset_t *mask,
                      int *result) {
    struct pollfd *p = calloc((size_t)nfds, sizeof *p);
    struct handle **hs = calloc((size_t)nfds, sizeof *hs);
    if (!p || !hs) {
        free(p);
        free(hs);
        errno = ENOMEM;
        *result = -1;
        return 0;
    }
    nfds_t n = 0;
    int any = 0;
    for (int fd = 0; fd < nfds; fd++) {
        short ev = (short)((rd && FD_ISSET(fd, rd) ? POLLIN : 0) | (wr && FD_ISSET(fd, wr) ? POLLOUT : 0) |
                           (ex && FD_ISSET(fd, ex) ? POLLPRI : 0));
        if (ev) {
            any |= (hs[n] = get(fd)) != NULL;
            p[n++] = (struct pollfd){fd, ev, 0};
        }
    }
    int r = any ? emu_poll(p, hs, n, timeout_ns, mask) : 0;
    int err = errno;
    if (any && r >= 0) {
        r = 0;
        if (rd) FD_ZERO(rd);
        if (wr) FD_ZERO(wr);
        if (ex) FD_ZERO(ex);
        for (nfds_t i = 0; i < n && r >= 0; i++) {
            short re = p[i].revents;
            if (re & POLLNVAL) {
                r = -1;
                err = EBADF;
                break;
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
    for (nfds_t i = 0; i < n; i++)
        put(hs[i]);
    free(p);
    free(hs);
    errno = err;
    *result = r;
    return !any;
}

/* select's sets copied in (only the words nfds covers, as the kernel reads them), run, copied out. */
static int select_copy(int nfds, fd_set *rd, fd_set *wr, fd_set *ex, long long timeout_ns, const sigset_t *mask,
                       int *result) {
    if (!any_live() || nfds <= 0 || nfds > FD_SETSIZE)
        return 1;
    size_t bytes = ((size_t)nfds + 8 * sizeof(long) - 1) / (8 * sizeof(long)) * sizeof(long);
    fd_set c[3];
    fd_set *user[3] = {rd, wr, ex}, *mine[3] = {NULL, NULL, NULL};
    for (int i = 0; i < 3; i++) {
        if (!user[i])
            continue;
        FD_ZERO(&c[i]);
        if (copy_in(&c[i], user[i], bytes) < 0)
            return 1; /* the real call gives the EFAULT */
        mine[i] = &c[i];
    }
    if (emu_select(nfds, mine[0], mine[1], mine[2], timeout_ns, mask, result))
        return 1;
    int err = errno;
    for (int i = 0; i < 3 && *result >= 0; i++)
        if (user[i] && copy_out(user[i], mine[i], bytes) < 0)
            *result = -1, err = EFAULT;
    errno = err;
    return 0;
}

EXPORT int select(int nfds, fd_set *rd, fd_set *wr, fd_set *ex, struct timeval *tv) {
    struct timeval t;
    int r;
    long long start = now_ns(), ns = -1;
    if (tv && copy_in(&t, tv, sizeof t) == 0)
        ns = (long long)t.tv_sec * 1000000000LL + (long long)t.tv_usec * 1000LL;
    if ((tv && ns < 0) || select_copy(nfds, rd, wr, ex, ns, NULL, &r)) {
        resolve_select();
        return real_select(nfds, rd, wr, ex, tv);
    }
    if (tv) { /* Linux leaves the time not slept in the timeout */
        long long left = ns - (now_ns() - start);
        if (left < 0)
            left = 0;
        t.tv_sec = left / 1000000000LL;
        t.tv_usec = (left % 1000000000LL) / 1000;
        int err = errno;
        copy_out(tv, &t, sizeof t);
        errno = err;
    }
    return r;
}

EXPORT int pselect(int nfds, fd_set *rd, fd_set *wr, fd_set *ex, const struct timespec *t, const sigset_t *mask) {
    struct timespec tc;
    int r;
    long long ns = -1;
    if (t && copy_in(&tc, t, sizeof tc) == 0)
        ns = (long long)tc.tv_sec * 1000000000LL + tc.tv_nsec;
    if ((t && ns < 0) || select_copy(nfds, rd, wr, ex, ns, mask, &r)) {
        resolve_pselect();
        return real_pselect(nfds, rd, wr, ex, t, mask);
    }
    return r;
}

/* --------------------------------------------------------------------------------------------- dup */
/* newfd (a result of dup/dup2/dup3/F_DUPFD of oldfd, whose handle h is held by the caller) now refers to
 * h's file, or to no emulated one: a dup2 onto an emulated fd closed that one. */
static int duped(struct handle *h, int oldfd, int newfd) {
    if (newfd >= 0 && newfd != oldfd && (h || emulated(newfd)))
        put(set_slot(newfd, h));
    put(h);
    return newfd;
}

EXPORT int dup(int fd) {
    struct handle *h = get(fd);
    resolve_dup();
    return duped(h, fd, real_dup(fd));
}

EXPORT int dup2(int fd, int fd2) {
    struct handle *h = get(fd);
    resolve_dup2();
    int r = real_dup2(fd, fd2);
    return duped(h, fd, r);
}

EXPORT int dup3(int fd, int fd2, int flags) {
    struct handle *h = get(fd);
    resolve_dup3();
    int r = real_dup3(fd, fd2, flags);
    return duped(h, fd, r);
}

static int fcntl_common(int (*real)(int, int, ...), int fd, int cmd, void *arg) {
    if (cmd != F_DUPFD && cmd != F_DUPFD_CLOEXEC)
        return real(fd, cmd, arg);
    struct handle *h = get(fd);
    return duped(h, fd, real(fd, cmd, arg));
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

/* -------------------------------------------------------------------------------------------- fork */
static pthread_mutex_t dirs_lock = PTHREAD_MUTEX_INITIALIZER;

/* A connection for a forked child to h's file, made in the parent before the fork; -1 when none. */
static int attach_for_child(struct handle *h) {
    int s = dial();
    if (s < 0)
        return -1;
    struct rollcam_req q = {OP_ATTACH, 0, (uint64_t)h->file, 0, 0};
    struct rollcam_rsp r;
    if (xfer(s, &q, NULL, NULL, 0, &r, NULL, NULL) < 0 || r.err) {
        real_close(s);
        return -1;
    }
    return s;
}

static void fork_prepare(void) {
    pthread_mutex_lock(&dirs_lock);
    pthread_mutex_lock(&table_lock);
    for (struct handle *h = live; h; h = h->next)
        h->child_ctl = h->slots ? attach_for_child(h) : -1;
}

static void fork_parent(void) {
    resolve_close();
    for (struct handle *h = live; h; h = h->next) {
        if (h->child_ctl >= 0)
            real_close(h->child_ctl);
        h->child_ctl = -1;
    }
    pthread_mutex_unlock(&table_lock);
    pthread_mutex_unlock(&dirs_lock);
}

/* Only this thread lives on in the child: the other threads' calls hold no references and their locks are
 * reset; each handle takes the connection made for it and drops the parent's. */
static void fork_child(void) {
    resolve_close();
    for (struct handle **p = &live; *p;) {
        struct handle *h = *p;
        real_close(h->ctl);
        h->ctl = h->child_ctl;
        h->child_ctl = -1;
        h->dead = h->ctl < 0;
        h->refs = h->slots;
        pthread_mutex_init(&h->lock, NULL);
        if (h->slots) {
            p = &h->next;
            continue;
        }
        __atomic_store_n(p, h->next, __ATOMIC_RELAXED); /* closed in the parent while a call held it */
        if (h->ctl >= 0)
            real_close(h->ctl);
        real_close(h->waitfd);
        real_close(h->evfd);
        free(h);
    }
    pthread_mutex_init(&table_lock, NULL);
    pthread_mutex_init(&dirs_lock, NULL);
}

/* ------------------------------------------------------------------------------------------- layout */
/* The wire format this library was built with, for the test that holds it to rollcam.emu.preload.wire's
 * reading of rollcam_wire.h: magic, version, the three structs' sizes, the ops; returns how many. */
EXPORT int64_t rollcam_preload_wire(int64_t *out, int64_t n) {
    const int64_t v[] = {ROLLCAM_WIRE_MAGIC, ROLLCAM_WIRE_VERSION, ROLLCAM_WIRE_MAX_PAYLOAD, ROLLCAM_WIRE_MAX_FDS,
                         sizeof(struct rollcam_hello), sizeof(struct rollcam_req), sizeof(struct rollcam_rsp),
                         offsetof(struct rollcam_req, a), offsetof(struct rollcam_rsp, err),
                         OP_OPEN, OP_IOCTL, OP_MMAP, OP_READ, OP_POLL, OP_CLOSE, OP_ATTACH};
    int64_t k = (int64_t)(sizeof v / sizeof v[0]);
    for (int64_t i = 0; i < k && i < n; i++)
        out[i] = v[i];
    return k;
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
    struct handle *h = get(fd); \
    if (h) { fill_stat((struct stat *)(st), h->minor); put(h); return 0; } \
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
        struct handle *h = get(dirfd);
        m = h ? h->minor : -1;
        put(h);
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
static struct dir_state dirs[8]; /* dirs_lock */

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
        if (emulated((int)a[0]))
            return ioctl((int)a[0], (unsigned long)a[1], (void *)a[2]);
        break;
    case SYS_openat:
        if (device_index((const char *)a[1]) >= 0)
            return emu_open(device_index((const char *)a[1]), (const char *)a[1], (int)a[2]);
        break;
    case SYS_close:
        if (emulated((int)a[0]))
            return close((int)a[0]);
        break;
    case SYS_read:
        if (emulated((int)a[0]))
            return read((int)a[0], (void *)a[1], (size_t)a[2]);
        break;
    case SYS_mmap:
        if (emulated((int)a[4]))
            return (long)mmap((void *)a[0], (size_t)a[1], (int)a[2], (int)a[3], (int)a[4], (off_t)a[5]);
        break;
    default:
        break;
    }
    resolve_syscall();
    return real_syscall(number, a[0], a[1], a[2], a[3], a[4], a[5]);
}
