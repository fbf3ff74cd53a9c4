/*
 * sandbox.c -- confine an isolated FMU's process (cosim/sandbox.py) before it loads the FMU.
 *
 * sandbox_enter is called once, in the child, after the FMU is unpacked and before its binary
 * is loaded; it cannot be undone. Each layer is asked of the kernel separately, and the result
 * says which ones hold (HOLD_*), so that a kernel without one (no user namespaces, no Landlock,
 * another architecture) keeps the others:
 *   - a user and network namespace: no network interface but a loopback that is down; and a
 *     mount namespace in which the scratch folder is a tmpfs of its own size (its quota);
 *   - limits: private writable memory (RLIMIT_DATA), address space (RLIMIT_AS, which counts
 *     shared mappings too), CPU time (RLIMIT_CPU), the size of a file it writes (RLIMIT_FSIZE),
 *     threads (RLIMIT_NPROC, where it has a user namespace of its own: counted there), no
 *     core files;
 *   - no new privileges (set-user-ID programs run without theirs);
 *   - Landlock: files are written only beneath the scratch folder (and /dev/null, and its own
 *     /proc/PID, where threads are named), no device
 *     it opens takes an ioctl (a terminal's settings: ABI 5), and, where
 *     asked (sandbox_read), read only beneath the paths given; no TCP bind or connect; no
 *     signals to, or abstract sockets of, processes outside the sandbox;
 *   - a session of its own (setsid): no controlling terminal to type into; the first process
 *     the kernel ends when memory runs out (oom_score_adj 1000);
 *   - seccomp (x86_64): the calls an FMU has no business making stop the process (SIGSYS),
 *     after one line naming the attempt on the report pipe: a network socket, a new process or
 *     program, a writable mapping larger than the memory limit, an open for writing that
 *     Landlock refuses, input pushed into a terminal (ioctl TIOCSTI, TIOCLINUX, TIOCSCTTY),
 *     a change to a file's mode, owner, times or extended attributes outside the scratch
 *     folder's file system (Landlock's rights do not cover them; within it, the change is
 *     reported done and not made), the prctl options that would let it outlive flexff or be traced
 *     (PR_SET_PDEATHSIG, PR_SET_DUMPABLE, PR_SET_PTRACER, PR_SET_MM), another process's limits
 *     (prlimit64: the master's CPU time would kill it), and the kernel's administrative calls.
 * An open for writing is trapped and then made again by the handler, from the one instruction
 * the filter lets through (sandbox_syscall_return), so that Landlock decides and the handler
 * can name the path it refused. An FMU that calls that instruction itself can only open files;
 * Landlock still decides which.
 */

#define _GNU_SOURCE

#include <errno.h>
#include <fcntl.h>
#include <linux/audit.h>
#include <linux/capability.h>
#include <linux/filter.h>
#include <linux/seccomp.h>
#include <sched.h>
#include <signal.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/mount.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/types.h>
#include <ucontext.h>
#include <unistd.h>

enum {
    HOLD_NAMESPACES = 1,
    HOLD_LIMITS = 2,
    HOLD_NO_NEW_PRIVILEGES = 4,
    HOLD_LANDLOCK_FILES = 8,
    HOLD_LANDLOCK_NETWORK = 16,
    HOLD_LANDLOCK_SCOPE = 32,
    HOLD_SECCOMP = 64,
    HOLD_SESSION = 128,
    HOLD_SCRATCH_QUOTA = 256,
    HOLD_LANDLOCK_READS = 512,
};
/* The address space beyond the memory limit (RLIMIT_AS): the interpreter, the libraries and
 * the threads' stacks, ~0.1-0.3 GB; small enough that shared mappings stay near the limit. */
#define ADDRESS_SLACK (512ULL << 20)
enum { STOPPED = 86 }; /* the exit status of a process the sandbox stopped (SANDBOX_STATUS) */

/* Landlock's ABI (linux/landlock.h), spelt out: the build machine's headers may predate it. */
enum { LANDLOCK_CREATE_RULESET = 444, LANDLOCK_ADD_RULE = 445, LANDLOCK_RESTRICT_SELF = 446 };
enum { LANDLOCK_VERSION_FLAG = 1, LANDLOCK_PATH_BENEATH = 1 };
#define FS_EXECUTE (1ULL << 0)
#define FS_WRITE_FILE (1ULL << 1)
#define FS_READ_FILE (1ULL << 2)
#define FS_READ_DIR (1ULL << 3)
#define FS_READS (FS_EXECUTE | FS_READ_FILE | FS_READ_DIR)
#define FS_WRITES                                                                           \
    (FS_WRITE_FILE | (1ULL << 4) | (1ULL << 5) | (1ULL << 6) | (1ULL << 7) | (1ULL << 8) | \
     (1ULL << 9) | (1ULL << 10) | (1ULL << 11) | (1ULL << 12)) /* write, remove, make */
#define FS_REFER (1ULL << 13)                                  /* ABI 2 */
#define FS_TRUNCATE (1ULL << 14)                               /* ABI 3 */
#define FS_IOCTL_DEV (1ULL << 15)                              /* ABI 5 */
#define NET_TCP ((1ULL << 0) | (1ULL << 1))                    /* ABI 4: bind, connect */
#define SCOPES ((1ULL << 0) | (1ULL << 1))                     /* ABI 6: abstract sockets, signals */

struct ruleset {
    uint64_t fs, net, scoped;
};
struct path_beneath {
    uint64_t allowed;
    int32_t fd;
} __attribute__((packed));

static int report_fd = -1;
static unsigned long long memory_limit; /* bytes */
static dev_t scratch_device;            /* the scratch folder's file system (its own tmpfs) */

/* -- the one instruction the filter lets an open for writing through --------------------- */
#if defined(__x86_64__)
__attribute__((visibility("hidden"))) long sandbox_syscall(long nr, long a, long b, long c,
                                                         long d, long e, long f);
__attribute__((visibility("hidden"))) extern const char sandbox_syscall_return[];
__asm__(".text\n"
        ".hidden sandbox_syscall\n"
        ".hidden sandbox_syscall_return\n"
        "sandbox_syscall:\n"
        "  movq %rdi, %rax\n"
        "  movq %rsi, %rdi\n"
        "  movq %rdx, %rsi\n"
        "  movq %rcx, %rdx\n"
        "  movq %r8, %r10\n"
        "  movq %r9, %r8\n"
        "  movq 8(%rsp), %r9\n"
        "  syscall\n"
        "sandbox_syscall_return:\n"
        "  ret\n");
#endif

/* -- the report: one line, built without calls that are unsafe in a signal handler -------- */
typedef struct {
    char text[600];
    size_t n;
} Line;

static void add(Line *line, const char *s) {
    while (*s && line->n < sizeof line->text - 2) line->text[line->n++] = *s++;
}

static void add_number(Line *line, unsigned long long value) {
    char digits[24];
    int k = 0;
    do digits[k++] = (char)('0' + value % 10);
    while ((value /= 10) && k < 24);
    while (k && line->n < sizeof line->text - 2) line->text[line->n++] = digits[--k];
}

static void add_path(Line *line, const char *path) {
    size_t k = 0;
    for (; path != NULL && path[k] && k < 400; k++) {
        char c = path[k];
        if (line->n >= sizeof line->text - 2) break;
        line->text[line->n++] = (c >= 32 && c < 127) ? c : '?';
    }
}

static void stop(Line *line) {
    line->text[line->n++] = '\n';
    if (report_fd >= 0) {
        ssize_t ignored = write(report_fd, line->text, line->n);
        (void)ignored;
    }
    syscall(SYS_exit_group, STOPPED);
}

#if defined(__x86_64__)
/* The calls that stop the process whatever their arguments, and what the report calls them. */
enum { ADMIN, METADATA_FIRST, METADATA_SECOND, METADATA_FD }; /* where a metadata call's path is */
enum { SYS_fchmodat2_ = 452, SYS_setxattrat_ = 463, SYS_removexattrat_ = 466 }; /* 6.6, 6.13 */
static const struct {
    int nr;
    const char *name;
    int kind;
} STOPPED_CALLS[] = {
    {SYS_ptrace, "ptrace", ADMIN}, {SYS_process_vm_readv, "process_vm_readv", ADMIN},
    {SYS_process_vm_writev, "process_vm_writev", ADMIN}, {SYS_mount, "mount", ADMIN},
    {SYS_umount2, "umount2", ADMIN}, {SYS_pivot_root, "pivot_root", ADMIN},
    {SYS_chroot, "chroot", ADMIN}, {SYS_unshare, "unshare", ADMIN}, {SYS_setns, "setns", ADMIN},
    {SYS_bpf, "bpf", ADMIN}, {SYS_perf_event_open, "perf_event_open", ADMIN},
    {SYS_kexec_load, "kexec_load", ADMIN}, {SYS_kexec_file_load, "kexec_file_load", ADMIN},
    {SYS_init_module, "init_module", ADMIN}, {SYS_finit_module, "finit_module", ADMIN},
    {SYS_delete_module, "delete_module", ADMIN}, {SYS_reboot, "reboot", ADMIN},
    {SYS_swapon, "swapon", ADMIN}, {SYS_swapoff, "swapoff", ADMIN}, {SYS_keyctl, "keyctl", ADMIN},
    {SYS_add_key, "add_key", ADMIN}, {SYS_request_key, "request_key", ADMIN},
    {SYS_io_uring_setup, "io_uring_setup", ADMIN}, {SYS_io_uring_enter, "io_uring_enter", ADMIN},
    {SYS_io_uring_register, "io_uring_register", ADMIN},
    {SYS_userfaultfd, "userfaultfd", ADMIN}, {SYS_acct, "acct", ADMIN}, {SYS_iopl, "iopl", ADMIN},
    {SYS_ioperm, "ioperm", ADMIN}, {SYS_settimeofday, "settimeofday", ADMIN},
    {SYS_clock_settime, "clock_settime", ADMIN}, {SYS_sethostname, "sethostname", ADMIN},
    {SYS_setdomainname, "setdomainname", ADMIN}, {SYS_pidfd_getfd, "pidfd_getfd", ADMIN},
    {SYS_kcmp, "kcmp", ADMIN},
    /* a file's mode, owner, times and extended attributes: no Landlock right covers them */
    {SYS_chmod, "chmod", METADATA_FIRST}, {SYS_fchmod, "fchmod", METADATA_FD},
    {SYS_fchmodat, "fchmodat", METADATA_SECOND}, {SYS_fchmodat2_, "fchmodat2", METADATA_SECOND},
    {SYS_chown, "chown", METADATA_FIRST}, {SYS_fchown, "fchown", METADATA_FD},
    {SYS_lchown, "lchown", METADATA_FIRST}, {SYS_fchownat, "fchownat", METADATA_SECOND},
    {SYS_utime, "utime", METADATA_FIRST}, {SYS_utimes, "utimes", METADATA_FIRST},
    {SYS_futimesat, "futimesat", METADATA_SECOND}, {SYS_utimensat, "utimensat", METADATA_SECOND},
    {SYS_setxattr, "setxattr", METADATA_FIRST}, {SYS_lsetxattr, "lsetxattr", METADATA_FIRST},
    {SYS_fsetxattr, "fsetxattr", METADATA_FD}, {SYS_removexattr, "removexattr", METADATA_FIRST},
    {SYS_lremovexattr, "lremovexattr", METADATA_FIRST},
    {SYS_fremovexattr, "fremovexattr", METADATA_FD},
    {SYS_setxattrat_, "setxattrat", METADATA_SECOND},
    {SYS_removexattrat_, "removexattrat", METADATA_SECOND},
};
enum { N_STOPPED_CALLS = sizeof STOPPED_CALLS / sizeof STOPPED_CALLS[0] };

/* The ioctl requests and prctl options that stop the process, by name. */
enum { TIOCSCTTY_ = 0x540E, TIOCSTI_ = 0x5412, TIOCLINUX_ = 0x541C };
static const struct {
    unsigned value;
    const char *name;
} TERMINAL_REQUESTS[] = {{TIOCSTI_, "TIOCSTI"}, {TIOCLINUX_, "TIOCLINUX"},
                         {TIOCSCTTY_, "TIOCSCTTY"}},
  PRCTL_OPTIONS[] = {{PR_SET_PDEATHSIG, "PR_SET_PDEATHSIG"}, {PR_SET_DUMPABLE, "PR_SET_DUMPABLE"},
                     {PR_SET_MM, "PR_SET_MM"}, {0x59616d61, "PR_SET_PTRACER"}};
enum { N_TERMINAL_REQUESTS = 3, N_PRCTL_OPTIONS = 4 };

/* An open for writing: made again from the allowed instruction; Landlock's refusal stops. */
static void reopen(greg_t *r, long nr, Line *line) {
    long result = sandbox_syscall(nr, r[REG_RDI], r[REG_RSI], r[REG_RDX], r[REG_R10],
                                  r[REG_R8], r[REG_R9]);
    if (result != -EACCES && result != -EPERM) {
        r[REG_RAX] = result;
        return;
    }
    const char *path = (const char *)(nr == SYS_openat ? r[REG_RSI] : r[REG_RDI]);
    add(line, "it tried to write to ");
    add_path(line, path);
    add(line, ", outside its scratch folder");
    stop(line);
}

/* A metadata call is never made. Its file looked up (followed where it is a symbolic link):
 * on the scratch folder's file system, the FMU's own, the call is reported done; where the
 * lookup fails, that failure is its result (nothing changed either way); 1 if so. Anywhere
 * else the process stops (0). */
static int metadata_answered(greg_t *r, int kind) {
    struct stat status;
    long path = kind == METADATA_FIRST ? r[REG_RDI] : kind == METADATA_SECOND ? r[REG_RSI] : 0;
    long found = path != 0 ? sandbox_syscall(SYS_newfstatat, kind == METADATA_FIRST ? AT_FDCWD
                                                              : r[REG_RDI],
                                             path, (long)&status, 0, 0, 0)
                           : sandbox_syscall(SYS_fstat, r[REG_RDI], (long)&status, 0, 0, 0, 0);
    if (found == 0 && status.st_dev != scratch_device) return 0;
    r[REG_RAX] = found;
    return 1;
}

static void on_sigsys(int number, siginfo_t *info, void *context) {
    (void)number;
    greg_t *r = ((ucontext_t *)context)->uc_mcontext.gregs;
    long nr = info->si_syscall;
    Line line = {{0}, 0};
    if (nr == SYS_open || nr == SYS_openat || nr == SYS_creat) {
        reopen(r, nr, &line);
        return;
    }
    for (int k = 0; k < N_STOPPED_CALLS; k++)
        if (STOPPED_CALLS[k].nr == nr && STOPPED_CALLS[k].kind != ADMIN &&
            metadata_answered(r, STOPPED_CALLS[k].kind))
            return;
    if (nr == SYS_socket) {
        add(&line, "it tried to open a network socket (address family ");
        add_number(&line, (unsigned long long)r[REG_RDI]);
        add(&line, ")");
    } else if (nr == SYS_clone || nr == SYS_fork || nr == SYS_vfork) {
        add(&line, "it tried to start a process");
    } else if (nr == SYS_execve || nr == SYS_execveat) {
        add(&line, "it tried to run a program");
        if (nr == SYS_execve) {
            add(&line, ": ");
            add_path(&line, (const char *)r[REG_RDI]);
        }
    } else if (nr == SYS_mmap || nr == SYS_mremap) {
        add(&line, "it tried to allocate ");
        add_number(&line, (unsigned long long)r[nr == SYS_mmap ? REG_RSI : REG_RDX] >> 20);
        add(&line, " MB, over its memory limit of ");
        add_number(&line, memory_limit >> 20);
        add(&line, " MB");
    } else if (nr == SYS_ioctl) {
        const char *name = "?";
        for (int k = 0; k < N_TERMINAL_REQUESTS; k++)
            if (TERMINAL_REQUESTS[k].value == (unsigned)r[REG_RSI]) name = TERMINAL_REQUESTS[k].name;
        add(&line, "it tried to push input into a terminal (ioctl ");
        add(&line, name);
        add(&line, ")");
    } else if (nr == SYS_prlimit64) {
        add(&line, "it tried to change the limits of process ");
        add_number(&line, (unsigned long long)r[REG_RDI]);
        add(&line, " (prlimit64)");
    } else if (nr == SYS_prctl) {
        const char *name = "?";
        for (int k = 0; k < N_PRCTL_OPTIONS; k++)
            if (PRCTL_OPTIONS[k].value == (unsigned)r[REG_RDI]) name = PRCTL_OPTIONS[k].name;
        add(&line, (unsigned)r[REG_RDI] == PR_SET_PDEATHSIG
                       ? "it tried to outlive flexff (prctl "
                       : "it made a forbidden system call (prctl ");
        add(&line, name);
        add(&line, ")");
    } else {
        int k = 0;
        while (k < N_STOPPED_CALLS && STOPPED_CALLS[k].nr != nr) k++;
        const char *name = k < N_STOPPED_CALLS ? STOPPED_CALLS[k].name : "a system call";
        int kind = k < N_STOPPED_CALLS ? STOPPED_CALLS[k].kind : ADMIN;
        if (kind == ADMIN) {
            add(&line, "it made a forbidden system call (");
            add(&line, name);
            add(&line, ")");
        } else {
            add(&line, "it tried to change a file's mode, owner, times or attributes (");
            add(&line, name);
            const char *path = (const char *)(kind == METADATA_FIRST    ? r[REG_RDI]
                                              : kind == METADATA_SECOND ? r[REG_RSI]
                                                                        : 0);
            if (path != NULL) {
                add(&line, " ");
                add_path(&line, path);
            }
            add(&line, ")");
        }
    }
    stop(&line);
}

/* -- the seccomp filter ------------------------------------------------------------------ */
#define STMT(code, k) ((struct sock_filter)BPF_STMT((code), (k)))
#define JUMP(code, k, yes, no) ((struct sock_filter)BPF_JUMP((code), (k), (yes), (no)))
#define LOAD(offset) STMT(BPF_LD | BPF_W | BPF_ABS, (offset))
#define IF(value, yes, no) JUMP(BPF_JMP | BPF_JEQ | BPF_K, (value), (yes), (no))
#define RETURN(action) STMT(BPF_RET | BPF_K, (action))
#define ARG_LO(k) (offsetof(struct seccomp_data, args) + 8 * (k))
#define ARG_HI(k) (ARG_LO(k) + 4)
#define NR offsetof(struct seccomp_data, nr)
#define TRAP SECCOMP_RET_TRAP
#define ALLOW SECCOMP_RET_ALLOW
#define FAIL(e) (SECCOMP_RET_ERRNO | (e))
#define WRITE_FLAGS (O_WRONLY | O_RDWR | O_CREAT | O_TRUNC)

enum { MAX_FILTER = 256 };

typedef struct {
    struct sock_filter code[MAX_FILTER];
    unsigned short n;
} Filter;

static void emit(Filter *f, struct sock_filter instruction) {
    if (f->n < MAX_FILTER) f->code[f->n++] = instruction;
}

/* `nr` goes to the block that follows (its length `block`), every other call skips it. */
static void on_call(Filter *f, int nr, unsigned char block) {
    emit(f, LOAD(NR));
    emit(f, IF((unsigned)nr, 0, block));
}

/* Trap when the 64-bit argument k is above `limit`, else allow (5 instructions). */
static void above(Filter *f, int k, unsigned long long limit) {
    emit(f, LOAD(ARG_HI(k)));
    emit(f, JUMP(BPF_JMP | BPF_JGT | BPF_K, (uint32_t)(limit >> 32), 3, 0));
    emit(f, IF((uint32_t)(limit >> 32), 0, 3));
    emit(f, LOAD(ARG_LO(k)));
    emit(f, JUMP(BPF_JMP | BPF_JGT | BPF_K, (uint32_t)limit, 0, 1));
    emit(f, RETURN(TRAP));
    emit(f, RETURN(ALLOW));
}

/* An open (flags in argument k; k < 0: creat, which always writes) traps when it may write,
 * unless it comes from the handler's instruction. */
static void open_call(Filter *f, int nr, int k) {
    uint64_t from = (uint64_t)(uintptr_t)sandbox_syscall_return;
    on_call(f, nr, k < 0 ? 6 : 8);
    emit(f, LOAD(offsetof(struct seccomp_data, instruction_pointer)));
    emit(f, IF((uint32_t)from, 0, 2));
    emit(f, LOAD(offsetof(struct seccomp_data, instruction_pointer) + 4));
    emit(f, IF((uint32_t)(from >> 32), k < 0 ? 1 : 3, 0));
    if (k >= 0) {
        emit(f, LOAD(ARG_LO(k)));
        emit(f, JUMP(BPF_JMP | BPF_JSET | BPF_K, WRITE_FLAGS, 0, 1));
    }
    emit(f, RETURN(TRAP));
    emit(f, RETURN(ALLOW));
}

/* Trap when argument k (its low 32 bits) is one of `values`, else allow. */
static void trap_if_one_of(Filter *f, int k, const unsigned *values, unsigned char n) {
    emit(f, LOAD(ARG_LO(k)));
    for (unsigned char i = 0; i < n; i++) emit(f, IF(values[i], (unsigned char)(n - i), 0));
    emit(f, RETURN(ALLOW));
    emit(f, RETURN(TRAP));
}

static int install_filter(void) {
    Filter f = {.n = 0};
    emit(&f, LOAD(offsetof(struct seccomp_data, arch)));
    emit(&f, IF(AUDIT_ARCH_X86_64, 1, 0));
    emit(&f, RETURN(SECCOMP_RET_KILL_PROCESS));
    emit(&f, LOAD(NR));
    emit(&f, JUMP(BPF_JMP | BPF_JGE | BPF_K, 0x40000000u, 0, 1)); /* the x32 ABI */
    emit(&f, RETURN(SECCOMP_RET_KILL_PROCESS));
    /* socket: AF_UNIX refused quietly (name lookups try it), any other family stops */
    on_call(&f, SYS_socket, 4);
    emit(&f, LOAD(ARG_LO(0)));
    emit(&f, IF(AF_UNIX, 0, 1));
    emit(&f, RETURN(FAIL(EACCES)));
    emit(&f, RETURN(TRAP));
    /* clone: threads only; clone3 hides its flags, so libc falls back to clone */
    on_call(&f, SYS_clone, 4);
    emit(&f, LOAD(ARG_LO(0)));
    emit(&f, JUMP(BPF_JMP | BPF_JSET | BPF_K, CLONE_THREAD, 0, 1));
    emit(&f, RETURN(ALLOW));
    emit(&f, RETURN(TRAP));
    on_call(&f, SYS_clone3, 1);
    emit(&f, RETURN(FAIL(ENOSYS)));
    on_call(&f, SYS_openat2, 1);
    emit(&f, RETURN(FAIL(ENOSYS)));
    /* the handler of SIGSYS stays the sandbox's */
    on_call(&f, SYS_rt_sigaction, 3);
    emit(&f, LOAD(ARG_LO(0)));
    emit(&f, IF(SIGSYS, 0, 1));
    emit(&f, RETURN(FAIL(EPERM)));
    /* writable mappings larger than the memory limit */
    on_call(&f, SYS_mmap, 10);
    emit(&f, LOAD(ARG_LO(2)));
    emit(&f, JUMP(BPF_JMP | BPF_JSET | BPF_K, PROT_WRITE, 1, 0));
    emit(&f, RETURN(ALLOW));
    above(&f, 1, memory_limit);
    on_call(&f, SYS_mremap, 7);
    above(&f, 2, memory_limit);
    open_call(&f, SYS_openat, 2);
    open_call(&f, SYS_open, 1);
    open_call(&f, SYS_creat, -1);
    unsigned requests[N_TERMINAL_REQUESTS], options[N_PRCTL_OPTIONS];
    for (int k = 0; k < N_TERMINAL_REQUESTS; k++) requests[k] = TERMINAL_REQUESTS[k].value;
    for (int k = 0; k < N_PRCTL_OPTIONS; k++) options[k] = PRCTL_OPTIONS[k].value;
    on_call(&f, SYS_ioctl, N_TERMINAL_REQUESTS + 3);
    trap_if_one_of(&f, 1, requests, N_TERMINAL_REQUESTS);
    on_call(&f, SYS_prctl, N_PRCTL_OPTIONS + 3);
    trap_if_one_of(&f, 0, options, N_PRCTL_OPTIONS);
    /* prlimit64 of another process (the master's CPU time, say): libc asks for its own, 0 */
    on_call(&f, SYS_prlimit64, 6);
    emit(&f, LOAD(ARG_LO(0)));
    emit(&f, IF(0, 0, 3));
    emit(&f, LOAD(ARG_HI(0)));
    emit(&f, IF(0, 0, 1));
    emit(&f, RETURN(ALLOW));
    emit(&f, RETURN(TRAP));
    /* the calls stopped whatever their arguments: one comparison each, one trap for all */
    static const int processes[] = {SYS_fork, SYS_vfork, SYS_execve, SYS_execveat};
    enum { N_PROCESSES = sizeof processes / sizeof processes[0] };
    unsigned char left = N_PROCESSES + N_STOPPED_CALLS;
    emit(&f, LOAD(NR));
    for (int k = 0; k < N_PROCESSES; k++, left--) emit(&f, IF((unsigned)processes[k], left, 0));
    for (int k = 0; k < N_STOPPED_CALLS; k++, left--)
        emit(&f, IF((unsigned)STOPPED_CALLS[k].nr, left, 0));
    emit(&f, RETURN(ALLOW));
    emit(&f, RETURN(TRAP));
    if (f.n >= MAX_FILTER) return -1;

    struct sigaction action;
    memset(&action, 0, sizeof action);
    action.sa_sigaction = on_sigsys;
    action.sa_flags = SA_SIGINFO;
    sigemptyset(&action.sa_mask);
    if (sigaction(SIGSYS, &action, NULL) != 0) return -1;
    sigset_t sys;
    sigemptyset(&sys);
    sigaddset(&sys, SIGSYS);
    sigprocmask(SIG_UNBLOCK, &sys, NULL);
    struct sock_fprog program = {f.n, f.code};
    return (int)syscall(SYS_seccomp, SECCOMP_SET_MODE_FILTER, SECCOMP_FILTER_FLAG_TSYNC,
                        &program);
}
#endif

/* -- the other layers -------------------------------------------------------------------- */
static int write_file(const char *path, const char *text) {
    int fd = open(path, O_WRONLY | O_CLOEXEC);
    if (fd < 0) return -1;
    ssize_t n = write(fd, text, strlen(text));
    close(fd);
    return n == (ssize_t)strlen(text) ? 0 : -1;
}

static void add_id_map(Line *line, unsigned id) {
    add_number(line, id);
    add(line, " ");
    add_number(line, id);
    add(line, " 1");
    line->text[line->n] = '\0';
}

/* A user namespace that maps this user to itself, and network, IPC and mount namespaces in
 * it; in the last, `scratch` becomes a tmpfs of `scratch_bytes` (its quota; <= 0: none) and
 * the working folder. The HOLD_* layers that hold. */
static int enter_namespaces(const char *scratch, long long scratch_bytes) {
    unsigned uid = (unsigned)getuid(), gid = (unsigned)getgid();
    if (unshare(CLONE_NEWUSER | CLONE_NEWNET | CLONE_NEWIPC | CLONE_NEWNS) != 0) return 0;
    Line uid_map = {{0}, 0}, gid_map = {{0}, 0};
    add_id_map(&uid_map, uid);
    add_id_map(&gid_map, gid);
    if (write_file("/proc/self/setgroups", "deny") != 0 ||
        write_file("/proc/self/uid_map", uid_map.text) != 0 ||
        write_file("/proc/self/gid_map", gid_map.text) != 0)
        return 0;
    int held = HOLD_NAMESPACES;
    if (scratch_bytes > 0) {
        Line options = {{0}, 0};
        add(&options, "size=");
        add_number(&options, (unsigned long long)scratch_bytes);
        add(&options, ",mode=700");
        options.text[options.n] = '\0';
        if (mount("flexff-scratch", scratch, "tmpfs", MS_NOSUID | MS_NODEV, options.text) == 0 &&
            chdir(scratch) == 0)
            held |= HOLD_SCRATCH_QUOTA;
    }
    struct __user_cap_header_struct header = {_LINUX_CAPABILITY_VERSION_3, 0};
    struct __user_cap_data_struct none[2];
    memset(none, 0, sizeof none);
    if (syscall(SYS_capset, &header, none) != 0) return 0; /* the namespace's capabilities */
    return held;
}

static int set_limits(double cpu_seconds, long long file_bytes, long threads) {
    rlim_t space = memory_limit + ADDRESS_SLACK;
    struct rlimit memory = {memory_limit, memory_limit}, address = {space, space},
                  no_core = {0, 0};
    int failed = setrlimit(RLIMIT_DATA, &memory) | setrlimit(RLIMIT_AS, &address) |
                 setrlimit(RLIMIT_CORE, &no_core);
    if (file_bytes > 0) {
        struct rlimit file = {(rlim_t)file_bytes, (rlim_t)file_bytes};
        failed |= setrlimit(RLIMIT_FSIZE, &file);
    }
    if (threads > 0) {
        struct rlimit tasks = {(rlim_t)threads, (rlim_t)threads};
        failed |= setrlimit(RLIMIT_NPROC, &tasks);
    }
    if (cpu_seconds > 0) {
        rlim_t soft = (rlim_t)(cpu_seconds + 0.999);
        struct rlimit cpu = {soft, soft + 1};
        failed |= setrlimit(RLIMIT_CPU, &cpu);
    }
    return failed;
}

static int add_beneath(int ruleset, const char *path, uint64_t allowed) {
    int fd = open(path, O_PATH | O_CLOEXEC);
    if (fd < 0) return -1;
    struct stat status;
    if (fstat(fd, &status) == 0 && !S_ISDIR(status.st_mode)) /* a file: its rights only */
        allowed &= FS_EXECUTE | FS_WRITE_FILE | FS_READ_FILE | FS_TRUNCATE | FS_IOCTL_DEV;
    struct path_beneath rule = {allowed, fd};
    int result = (int)syscall(LANDLOCK_ADD_RULE, ruleset, LANDLOCK_PATH_BENEATH, &rule, 0);
    close(fd);
    return result;
}

/* Writes beneath `scratch` only; with ABI 4 no TCP, with ABI 6 no reach outside; where
 * `readable` is given (paths, each ended by a NUL, the list by an empty one), reads beneath
 * them (and `scratch`) only. */
static int landlock(const char *scratch, const char *readable) {
    long abi = syscall(LANDLOCK_CREATE_RULESET, NULL, 0, LANDLOCK_VERSION_FLAG);
    if (abi < 1) return 0;
    uint64_t writes = FS_WRITES | (abi >= 2 ? FS_REFER : 0) | (abi >= 3 ? FS_TRUNCATE : 0) |
                      (abi >= 5 ? FS_IOCTL_DEV : 0); /* ioctl on a device it opens: a terminal */
    uint64_t reads = readable != NULL ? FS_READS : 0;
    struct ruleset attr = {writes | reads, abi >= 4 ? NET_TCP : 0, abi >= 6 ? SCOPES : 0};
    size_t size = abi >= 6 ? sizeof attr : abi >= 4 ? 2 * sizeof(uint64_t) : sizeof(uint64_t);
    int ruleset = (int)syscall(LANDLOCK_CREATE_RULESET, &attr, size, 0);
    if (ruleset < 0) return 0;
    int held = 0;
    uint64_t file_writes = FS_WRITE_FILE | (abi >= 3 ? FS_TRUNCATE : 0);
    int failed = add_beneath(ruleset, scratch, writes | reads) |
                 add_beneath(ruleset, "/dev/null", file_writes | reads);
    add_beneath(ruleset, "/proc/self", file_writes | reads); /* its own: a thread's name */
    for (const char *path = readable; path != NULL && *path; path += strlen(path) + 1)
        add_beneath(ruleset, path, reads); /* one that is not there is left out */
    if (failed == 0 && syscall(LANDLOCK_RESTRICT_SELF, ruleset, 0) == 0)
        held = HOLD_LANDLOCK_FILES | (abi >= 4 ? HOLD_LANDLOCK_NETWORK : 0) |
               (abi >= 6 ? HOLD_LANDLOCK_SCOPE : 0) | (reads ? HOLD_LANDLOCK_READS : 0);
    close(ruleset);
    return held;
}

/* Confine this process: `scratch` the only folder it writes to (a tmpfs of `scratch_bytes`
 * where the namespaces hold), `memory` bytes of private writable memory, `cpu_seconds` of CPU
 * time (<= 0: unbounded), `threads` threads at most (RLIMIT_NPROC, in its own user namespace
 * only; it does not bind root),
 * the report of a stopped attempt on `report`, reads beneath `readable` only where given
 * (landlock). Returns the HOLD_* layers that hold. */
__attribute__((visibility("default"))) int sandbox_enter(const char *scratch, long long memory,
                                                         double cpu_seconds, int report,
                                                         long long scratch_bytes, long threads,
                                                         const char *readable) {
    report_fd = report;
    memory_limit = (unsigned long long)memory;
    int held = 0;
    if (setsid() >= 0 || getsid(0) == getpid()) held |= HOLD_SESSION;
    /* the kernel's choice when memory runs out, before flexff: the memory it holds outside
     * its address space (a tmpfs, memfds) is not counted in flexff's favour otherwise */
    write_file("/proc/self/oom_score_adj", "1000");
    held |= enter_namespaces(scratch, scratch_bytes);
    /* RLIMIT_NPROC counts the user's processes in its user namespace: in the sandbox's own,
     * the FMU's threads; in the user's, every process of theirs, which it must not bound */
    long tasks = held & HOLD_NAMESPACES ? threads : 0;
    if (set_limits(cpu_seconds, scratch_bytes, tasks) == 0) held |= HOLD_LIMITS;
    struct stat scratch_status;
    scratch_device = stat(scratch, &scratch_status) == 0 ? scratch_status.st_dev : (dev_t)-1;
    if (prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0) return held;
    held |= HOLD_NO_NEW_PRIVILEGES;
    held |= landlock(scratch, readable);
#if defined(__x86_64__)
    if (install_filter() == 0) held |= HOLD_SECCOMP;
#endif
    return held;
}
