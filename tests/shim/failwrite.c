/* A fault-injection shim for the full-disk test (tests/e2e/full_disk.sh), loaded with LD_PRELOAD:
 * once LENSOPT_FAIL_WRITE_AFTER bytes have gone to regular files (stdout and stderr are never
 * counted), every further write to a regular file fails with ENOSPC ("No space left on device"),
 * as on a full disk. write, writev, pwrite and fwrite are covered (glibc's stdio calls its
 * internal write, so fwrite is caught at its entry); a write that crosses the limit is short. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

static atomic_llong g_written;

static long long limit_bytes(void) {
  static long long limit = -2;
  if (limit == -2) {
    const char* text = getenv("LENSOPT_FAIL_WRITE_AFTER");
    limit = text ? atoll(text) : -1;
  }
  return limit;
}

static int counted(int fd) {
  struct stat st;
  return fd > 2 && fstat(fd, &st) == 0 && S_ISREG(st.st_mode);
}

/* How many of n bytes may still be written to fd (n if not counted); -1 with ENOSPC if none. */
static long long allowance(int fd, long long n) {
  const long long limit = limit_bytes();
  if (limit < 0 || n <= 0 || !counted(fd)) return n;
  const long long before = atomic_fetch_add(&g_written, n);
  if (before + n <= limit) return n;
  const long long left = before < limit ? limit - before : 0;
  if (left == 0) {
    errno = ENOSPC;
    return -1;
  }
  return left;
}

ssize_t write(int fd, const void* buf, size_t n) {
  static ssize_t (*real)(int, const void*, size_t);
  if (!real) real = (ssize_t(*)(int, const void*, size_t))dlsym(RTLD_NEXT, "write");
  const long long ok = allowance(fd, (long long)n);
  if (ok < 0) return -1;
  return real(fd, buf, (size_t)ok);
}

ssize_t pwrite(int fd, const void* buf, size_t n, off_t offset) {
  static ssize_t (*real)(int, const void*, size_t, off_t);
  if (!real) real = (ssize_t(*)(int, const void*, size_t, off_t))dlsym(RTLD_NEXT, "pwrite");
  const long long ok = allowance(fd, (long long)n);
  if (ok < 0) return -1;
  return real(fd, buf, (size_t)ok, offset);
}

ssize_t writev(int fd, const struct iovec* iov, int count) {
  static ssize_t (*real)(int, const struct iovec*, int);
  if (!real) real = (ssize_t(*)(int, const struct iovec*, int))dlsym(RTLD_NEXT, "writev");
  long long total = 0;
  for (int i = 0; i < count; ++i) total += (long long)iov[i].iov_len;
  const long long ok = allowance(fd, total);
  if (ok < 0) return -1;
  if (ok == total) return real(fd, iov, count);
  /* Short: write the first `ok` bytes only. */
  ssize_t done = 0;
  long long left = ok;
  for (int i = 0; i < count && left > 0; ++i) {
    const size_t part =
        (size_t)(left < (long long)iov[i].iov_len ? left : (long long)iov[i].iov_len);
    static ssize_t (*real_write)(int, const void*, size_t);
    if (!real_write) real_write = (ssize_t(*)(int, const void*, size_t))dlsym(RTLD_NEXT, "write");
    const ssize_t w = real_write(fd, iov[i].iov_base, part);
    if (w < 0) return done > 0 ? done : -1;
    done += w;
    left -= w;
  }
  return done;
}

size_t fwrite(const void* buf, size_t size, size_t count, FILE* stream) {
  static size_t (*real)(const void*, size_t, size_t, FILE*);
  if (!real) real = (size_t(*)(const void*, size_t, size_t, FILE*))dlsym(RTLD_NEXT, "fwrite");
  if (size == 0 || count == 0) return 0;
  const long long n = (long long)size * (long long)count;
  const long long ok = allowance(fileno(stream), n);
  if (ok < 0) return 0;
  if (ok == n) return real(buf, size, count, stream);
  const size_t items = (size_t)(ok / (long long)size);
  const size_t written = items > 0 ? real(buf, size, items, stream) : 0;
  errno = ENOSPC;
  return written;
}
