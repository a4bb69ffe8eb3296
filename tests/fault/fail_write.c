/*
 * A file system that fails the N-th write, for tests (issue 63): loaded into a program with
 * LD_PRELOAD, it counts the writes (write, writev, pwrite, pwritev, fsync, fdatasync) to files
 * under a directory and makes one of them fail, as a full or failing disk would.
 *
 *   FAIL_WRITE_UNDER=DIR   count only writes to files whose path starts with DIR
 *   FAIL_WRITE_AT=N        the N-th of them fails (1 is the first; 0 or unset: none fails)
 *   FAIL_WRITE_ERRNO=E     with this errno (default 5, EIO; 28 is ENOSPC)
 *   FAIL_WRITE_COUNT=FILE  at exit, how many were counted, written into FILE
 *
 * Built by the test that uses it (cc -shared -fPIC -o fail_write.so fail_write.c -ldl).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <unistd.h>

static const char *under;
static size_t under_len;
static long fail_at;
static int fail_errno = EIO;
static long counted;

static ssize_t (*real_write)(int, const void *, size_t);
static ssize_t (*real_writev)(int, const struct iovec *, int);
static ssize_t (*real_pwrite)(int, const void *, size_t, off_t);
static ssize_t (*real_pwrite64)(int, const void *, size_t, off_t);
static ssize_t (*real_pwritev)(int, const struct iovec *, int, off_t);
static int (*real_fsync)(int);
static int (*real_fdatasync)(int);

__attribute__((constructor)) static void start(void) {
    real_write = dlsym(RTLD_NEXT, "write");
    real_writev = dlsym(RTLD_NEXT, "writev");
    real_pwrite = dlsym(RTLD_NEXT, "pwrite");
    real_pwrite64 = dlsym(RTLD_NEXT, "pwrite64");
    real_pwritev = dlsym(RTLD_NEXT, "pwritev");
    real_fsync = dlsym(RTLD_NEXT, "fsync");
    real_fdatasync = dlsym(RTLD_NEXT, "fdatasync");
    under = getenv("FAIL_WRITE_UNDER");
    under_len = under ? strlen(under) : 0;
    const char *at = getenv("FAIL_WRITE_AT");
    fail_at = at ? atol(at) : 0;
    const char *e = getenv("FAIL_WRITE_ERRNO");
    if (e && atoi(e) > 0) {
        fail_errno = atoi(e);
    }
}

__attribute__((destructor)) static void end(void) {
    const char *path = getenv("FAIL_WRITE_COUNT");
    if (!path) {
        return;
    }
    char text[32];
    int n = snprintf(text, sizeof text, "%ld\n", __atomic_load_n(&counted, __ATOMIC_SEQ_CST));
    int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
        real_write(fd, text, (size_t)n);
        close(fd);
    }
}

/* Whether this write to `fd` is the one that fails (and counts it when `fd` is under DIR). */
static int fails(int fd) {
    if (under_len == 0) {
        return 0;
    }
    char link[64], path[4096];
    snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    ssize_t n = readlink(link, path, sizeof path - 1);
    if (n < (ssize_t)under_len || strncmp(path, under, under_len) != 0) {
        return 0;
    }
    long k = __atomic_add_fetch(&counted, 1, __ATOMIC_SEQ_CST);
    if (k == fail_at) {
        errno = fail_errno;
        return 1;
    }
    return 0;
}

ssize_t write(int fd, const void *buf, size_t len) {
    return fails(fd) ? -1 : real_write(fd, buf, len);
}

ssize_t writev(int fd, const struct iovec *iov, int count) {
    return fails(fd) ? -1 : real_writev(fd, iov, count);
}

ssize_t pwrite(int fd, const void *buf, size_t len, off_t at) {
    return fails(fd) ? -1 : real_pwrite(fd, buf, len, at);
}

ssize_t pwrite64(int fd, const void *buf, size_t len, off_t at) {
    return fails(fd) ? -1 : real_pwrite64(fd, buf, len, at);
}

ssize_t pwritev(int fd, const struct iovec *iov, int count, off_t at) {
    return fails(fd) ? -1 : real_pwritev(fd, iov, count, at);
}

int fsync(int fd) {
    return fails(fd) ? -1 : real_fsync(fd);
}

int fdatasync(int fd) {
    return fails(fd) ? -1 : real_fdatasync(fd);
}
