/*
 * sandbox.c -- confine an isolated FMU's process (cosim/sandbox.py) before it loads the FMU.
 *
 * sandbox_enter is called once, in the child, after the FMU is unpacked and before its binary
 * is loaded; it cannot be undone. Each layer is asked of the kernel separately, and the result
 * says which ones hold (HOLD_*), so that a kernel without one (no user namespaces, no Landlock,
 * another architecture) keeps the others:
 *   - a user and network namespace: no network interface but a loopback that is down;
 *   - limits: private writable memory (RLIMIT_DATA), CPU time (RLIMIT_CPU), no core files;
 *   - no new privileges (set-user-ID programs run without theirs);
 *   - Landlock: files are written only beneath the scratch folder (and /dev/null); no TCP bind
 *     or connect; no signals to, or abstract sockets of, processes outside the sandbox;
 *   - seccomp (x86_64): the calls an FMU has no business making stop the process (SIGSYS),
 *     after one line naming the attempt on the report pipe: a network socket, a new process or
 *     program, a writable mapping larger than the memory limit, an open for writing that
 *     Landlock refuses, and the kernel's administrative calls.
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
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
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
};
enum { STOPPED = 86 }; /* the exit status of a process the sandbox stopped (SANDBOX_STATUS) */

/* Landlock's ABI (linux/landlock.h), spelt out: the build machine's headers may predate it. */
enum { LANDLOCK_CREATE_RULESET = 444, LANDLOCK_ADD_RULE = 445, LANDLOCK_RESTRICT_SELF = 446 };
enum { LANDLOCK_VERSION_FLAG = 1, LANDLOCK_PATH_BENEATH = 1 };
#define FS_WRITE_FILE (1ULL << 1)
#define FS_WRITES                                                                           \
    (FS_WRITE_FILE | (1ULL << 4) | (1ULL << 5) | (1ULL << 6) | (1ULL << 7) | (1ULL << 8) | \
     (1ULL << 9) | (1ULL << 10) | (1ULL << 11) | (1ULL << 12)) /* write, remove, make */
#define FS_REFER (1ULL << 13)                                  /* ABI 2 */
#define FS_TRUNCATE (1ULL << 14)                               /* ABI 3 */
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
static const struct {
    int nr;
    const char *name;
} ADMIN[] = {
    {SYS_ptrace, "ptrace"}, {SYS_process_vm_readv, "process_vm_readv"},
    {SYS_process_vm_writev, "process_vm_writev"}, {SYS_mount, "mount"},
    {SYS_umount2, "umount2"}, {SYS_pivot_root, "pivot_root"}, {SYS_chroot, "chroot"},
    {SYS_unshare, "unshare"}, {SYS_setns, "setns"}, {SYS_bpf, "bpf"},
    {SYS_perf_event_open, "perf_event_open"}, {SYS_kexec_load, "kexec_load"},
    {SYS_kexec_file_load, "kexec_file_load"}, {SYS_init_module, "init_module"},
    {SYS_finit_module, "finit_module"}, {SYS_delete_module, "delete_module"},
    {SYS_reboot, "reboot"}, {SYS_swapon, "swapon"}, {SYS_swapoff, "swapoff"},
    {SYS_keyctl, "keyctl"}, {SYS_add_key, "add_key"}, {SYS_request_key, "request_key"},
    {SYS_io_uring_setup, "io_uring_setup"}, {SYS_io_uring_enter, "io_uring_enter"},
    {SYS_io_uring_register, "io_uring_register"}, {SYS_userfaultfd, "userfaultfd"},
    {SYS_acct, "acct"}, {SYS_iopl, "iopl"}, {SYS_ioperm, "ioperm"},
    {SYS_settimeofday, "settimeofday"}, {SYS_clock_settime, "clock_settime"},
    {SYS_sethostname, "sethostname"}, {SYS_setdomainname, "setdomainname"},
};
enum { N_ADMIN = sizeof ADMIN / sizeof ADMIN[0] };

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

static void on_sigsys(int number, siginfo_t *info, void *context) {
    (void)number;
    greg_t *r = ((ucontext_t *)context)->uc_mcontext.gregs;
    long nr = info->si_syscall;
    Line line = {{0}, 0};
    if (nr == SYS_open || nr == SYS_openat || nr == SYS_creat) {
        reopen(r, nr, &line);
        return;
    }
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
    } else {
        const char *name = "a system call";
        for (int k = 0; k < N_ADMIN; k++)
            if (ADMIN[k].nr == nr) name = ADMIN[k].name;
        add(&line, "it made a forbidden system call (");
        add(&line, name);
        add(&line, ")");
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
    static const int stopped[] = {SYS_fork, SYS_vfork, SYS_execve, SYS_execveat};
    for (size_t k = 0; k < sizeof stopped / sizeof stopped[0]; k++) {
        on_call(&f, stopped[k], 1);
        emit(&f, RETURN(TRAP));
    }
    for (int k = 0; k < N_ADMIN; k++) {
        on_call(&f, ADMIN[k].nr, 1);
        emit(&f, RETURN(TRAP));
    }
    emit(&f, RETURN(ALLOW));
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

/* A user namespace that maps this user to itself, and a network namespace in it. */
static int enter_namespaces(void) {
    unsigned uid = (unsigned)getuid(), gid = (unsigned)getgid();
    if (unshare(CLONE_NEWUSER | CLONE_NEWNET | CLONE_NEWIPC) != 0) return -1;
    Line uid_map = {{0}, 0}, gid_map = {{0}, 0};
    add_id_map(&uid_map, uid);
    add_id_map(&gid_map, gid);
    if (write_file("/proc/self/setgroups", "deny") != 0 ||
        write_file("/proc/self/uid_map", uid_map.text) != 0 ||
        write_file("/proc/self/gid_map", gid_map.text) != 0)
        return -1;
    struct __user_cap_header_struct header = {_LINUX_CAPABILITY_VERSION_3, 0};
    struct __user_cap_data_struct none[2];
    memset(none, 0, sizeof none);
    return (int)syscall(SYS_capset, &header, none); /* the namespace's capabilities dropped */
}

static int set_limits(double cpu_seconds) {
    struct rlimit memory = {memory_limit, memory_limit}, no_core = {0, 0};
    int failed = setrlimit(RLIMIT_DATA, &memory) | setrlimit(RLIMIT_CORE, &no_core);
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
    struct path_beneath rule = {allowed, fd};
    int result = (int)syscall(LANDLOCK_ADD_RULE, ruleset, LANDLOCK_PATH_BENEATH, &rule, 0);
    close(fd);
    return result;
}

/* Writes beneath `scratch` only; with ABI 4 no TCP, with ABI 6 no reach outside. */
static int landlock(const char *scratch) {
    long abi = syscall(LANDLOCK_CREATE_RULESET, NULL, 0, LANDLOCK_VERSION_FLAG);
    if (abi < 1) return 0;
    uint64_t writes = FS_WRITES | (abi >= 2 ? FS_REFER : 0) | (abi >= 3 ? FS_TRUNCATE : 0);
    struct ruleset attr = {writes, abi >= 4 ? NET_TCP : 0, abi >= 6 ? SCOPES : 0};
    size_t size = abi >= 6 ? sizeof attr : abi >= 4 ? 2 * sizeof(uint64_t) : sizeof(uint64_t);
    int ruleset = (int)syscall(LANDLOCK_CREATE_RULESET, &attr, size, 0);
    if (ruleset < 0) return 0;
    int held = 0;
    uint64_t file_writes = FS_WRITE_FILE | (abi >= 3 ? FS_TRUNCATE : 0);
    if (add_beneath(ruleset, scratch, writes) == 0 &&
        add_beneath(ruleset, "/dev/null", file_writes) == 0 &&
        syscall(LANDLOCK_RESTRICT_SELF, ruleset, 0) == 0)
        held = HOLD_LANDLOCK_FILES | (abi >= 4 ? HOLD_LANDLOCK_NETWORK : 0) |
               (abi >= 6 ? HOLD_LANDLOCK_SCOPE : 0);
    close(ruleset);
    return held;
}

/* Confine this process: `scratch` the only folder it writes to, `memory` bytes of private
 * writable memory, `cpu_seconds` of CPU time (<= 0: unbounded), the report of a stopped
 * attempt on `report`. Returns the HOLD_* layers that hold. */
__attribute__((visibility("default"))) int sandbox_enter(const char *scratch, long long memory,
                                                         double cpu_seconds, int report) {
    report_fd = report;
    memory_limit = (unsigned long long)memory;
    int held = 0;
    if (enter_namespaces() == 0) held |= HOLD_NAMESPACES;
    if (set_limits(cpu_seconds) == 0) held |= HOLD_LIMITS;
    if (prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0) return held;
    held |= HOLD_NO_NEW_PRIVILEGES;
    held |= landlock(scratch);
#if defined(__x86_64__)
    if (install_filter() == 0) held |= HOLD_SECCOMP;
#endif
    return held;
}
