/*
 * probe_fmu.c -- a tiny FMI 2.0 co-simulation FMU for the tests (built by tests/probe_fmu.py).
 *
 * It records what the importer gave it and misbehaves on request:
 *   start_seen      the start time fmi2SetupExperiment gave (output)
 *   tolerance_seen  the tolerance it gave, -1 where none was defined (output)
 *   clock           the time of the current communication point (output)
 *   u -> y          y = 2 u, direct feedthrough (input, output)
 *   crash_at        fmi2DoStep from t >= crash_at raises SIGSEGV (parameter, -1: never)
 *   hang_at         fmi2DoStep from t >= hang_at never returns (parameter, -1: never)
 *   attempt         what fmi2DoStep tries once, from t >= attempt_at (parameters; what a
 *                   sandbox must stop, and an honest twin): 0 nothing, 1 open a network
 *                   socket, 2 write to ESCAPE, 3 allocate 10 GB, 4 start 64 processes, 5 run
 *                   /bin/true, 6 write and read back a file in its working directory (and
 *                   set its mode and times, and name a thread of its own),
 *                   7 push a command into the terminal (ioctl TIOCSTI on /dev/tty, stdin,
 *                   stdout, stderr), 8 shrink the memory it shares with an isolating master,
 *                   9 chmod, 10 set the times of, 11 set an extended attribute of OUTSIDE,
 *                   12 clear its parent-death signal, 13 truncate its stdout and stderr and
 *                   write 20 MB (with escape sequences and a forged flexff line) to them,
 *                   14 start 5000 threads, 15 map 1 GB of shared memory, 16 write 300 MB into
 *                   its working directory, 17 spin forever, 18 stop itself (SIGSTOP),
 *                   19 log a message with terminal escapes and fail, 20 read OUTSIDE,
 *                   21 limit the size of its parent's files to 0 (an isolating master dies of
 *                   SIGXFSZ as it writes its record), 22 read its parent's environment,
 *                   23 hang in fmi2Terminate
 * An instance named "hang_instantiate" never returns from fmi2Instantiate; the hostile probe
 * (GUID "{probe-hostile}") tries to write to ESCAPE in fmi2Instantiate.
 */

#include <dirent.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <sys/xattr.h>
#include <unistd.h>

#include "fmi2Functions.h"

enum { START, TOLERANCE, CLOCK, U, Y, CRASH_AT, HANG_AT, ATTEMPT, ATTEMPT_AT, N };
enum { NOTHING, SOCKET, ESCAPE_WRITE, ALLOCATE, PROCESSES, PROGRAM, SCRATCH_WRITE, TERMINAL,
       SHRINK_SHARED, CHMOD, TIMES, XATTR, ORPHAN, FLOOD, THREADS, SHARED_MAP, FILL, SPIN,
       STOP, LOG_ESCAPES, READ_OUTSIDE, LIMIT_PARENT, PARENT_ENVIRONMENT, HANG_TERMINATE };
#define ESCAPE "/tmp/flexff-probe-escape.txt"
#define OUTSIDE "/tmp/flexff-probe-outside.txt" /* a file the tests make, mode 0644 */
#define INJECTED "echo flexff-probe-injected\n"

typedef struct {
    fmi2Real v[N];
    fmi2CallbackLogger log;
    fmi2ComponentEnvironment env;
} Probe;

static fmi2Status attempt(Probe *p, int what);

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String location, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean logging) {
    (void)type; (void)location; (void)visible; (void)logging;
    while (name != NULL && strcmp(name, "hang_instantiate") == 0) pause();
    Probe *p = calloc(1, sizeof *p);
    if (p == NULL) return NULL;
    p->log = functions->logger;
    p->env = functions->componentEnvironment;
    if (guid != NULL && strcmp(guid, "{probe-hostile}") == 0 && attempt(p, ESCAPE_WRITE) != fmi2OK) {
        free(p);
        return NULL;
    }
    p->v[TOLERANCE] = -1.0;
    p->v[CRASH_AT] = -1.0;
    p->v[HANG_AT] = -1.0;
    return p;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolerance_defined,
                               fmi2Real tolerance, fmi2Real start, fmi2Boolean stop_defined,
                               fmi2Real stop) {
    Probe *p = c;
    (void)stop_defined; (void)stop;
    p->v[TOLERANCE] = tolerance_defined ? tolerance : -1.0;
    p->v[START] = start;
    p->v[CLOCK] = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) {
    Probe *p = c;
    while (p->v[ATTEMPT] == HANG_TERMINATE) pause();
    return fmi2OK;
}
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       fmi2Real value[]) {
    Probe *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N) return fmi2Error;
        value[i] = vr[i] == Y ? 2.0 * p->v[U] : p->v[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real value[]) {
    Probe *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != U && vr[i] < CRASH_AT) return fmi2Error;
        if (vr[i] >= N) return fmi2Error;
        p->v[vr[i]] = value[i];
    }
    return fmi2OK;
}

/* the version, logging, Integer, Boolean, String, state, derivative and step-status calls:
   tests/fmi2_unsupported.c */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)value;
    return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t n, const fmi2Integer order[], fmi2Real value[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)value;
    return fmi2Error;
}

static void *nap(void *unused) {
    (void)unused;
    usleep(1000);
    return NULL;
}

static void *idle(void *unused) {
    (void)unused;
    for (;;) pause();
    return NULL;
}

/* Every character of INJECTED pushed into the terminal behind `fd`; 0 if that worked. */
static int inject(int fd) {
    for (const char *c = INJECTED; *c; c++)
        if (ioctl(fd, TIOCSTI, c) != 0) return -1;
    return 0;
}

/* The memory an isolating master shares with this process, shrunk to nothing; 0 if done. */
static int shrink_shared(void) {
    DIR *fds = opendir("/proc/self/fd");
    if (fds == NULL) return -1;
    int done = -1;
    struct dirent *entry;
    while ((entry = readdir(fds)) != NULL) {
        char link[64], target[256] = {0};
        snprintf(link, sizeof link, "/proc/self/fd/%s", entry->d_name);
        if (readlink(link, target, sizeof target - 1) > 0 && strstr(target, "memfd:flexff"))
            if (ftruncate(atoi(entry->d_name), 0) == 0) done = 0;
    }
    closedir(fds);
    return done;
}

/* The attempt `what`; fmi2Error where the FMU itself sees it fail. */
static fmi2Status attempt(Probe *p, int what) {
    if (what == SOCKET) {
        int s = socket(AF_INET, SOCK_STREAM, 0);
        if (s < 0) return fmi2Error;
        close(s);
    } else if (what == ESCAPE_WRITE || what == SCRATCH_WRITE) {
        const char *path = what == ESCAPE_WRITE ? ESCAPE : "probe-note.txt";
        FILE *f = fopen(path, "w");
        if (f == NULL) return fmi2Error;
        fputs("probe", f);
        fclose(f);
        char back[8] = {0};
        f = fopen(path, "r");
        if (f == NULL || fread(back, 1, 5, f) != 5 || strcmp(back, "probe") != 0) return fmi2Error;
        fclose(f);
        if (what == SCRATCH_WRITE && (chmod(path, 0600) != 0 || utimensat(AT_FDCWD, path, NULL, 0)))
            return fmi2Error; /* its own file's metadata: as a library's cache may */
        pthread_t worker; /* a named thread, as a runtime's pool is (/proc/self/task/N/comm) */
        if (what == SCRATCH_WRITE && (pthread_create(&worker, NULL, nap, NULL) != 0 ||
                                      pthread_setname_np(worker, "probe-worker") != 0 ||
                                      pthread_join(worker, NULL) != 0))
            return fmi2Error;
    } else if (what == ALLOCATE) {
        char *memory = malloc((size_t)10 << 30);
        if (memory == NULL) return fmi2Error;
        memset(memory, 1, 1 << 20);
        free(memory);
    } else if (what == PROCESSES) {
        for (int k = 0; k < 64; k++) {
            pid_t child = fork();
            if (child == 0) _exit(0);
            if (child < 0) return fmi2Error;
            waitpid(child, NULL, 0);
        }
    } else if (what == PROGRAM) {
        pid_t child = fork();
        if (child == 0) {
            execl("/bin/true", "true", (char *)NULL);
            _exit(1);
        }
        if (child < 0) return fmi2Error;
        waitpid(child, NULL, 0);
    } else if (what == TERMINAL) {
        int tty = open("/dev/tty", O_RDONLY), pushed = -1;
        if (tty >= 0) pushed = inject(tty);
        for (int fd = 0; fd < 3 && pushed != 0; fd++) pushed = inject(fd);
        if (pushed != 0) return fmi2Error;
    } else if (what == SHRINK_SHARED) {
        if (shrink_shared() != 0) return fmi2Error;
    } else if (what == CHMOD) {
        if (chmod(OUTSIDE, 06777) != 0) return fmi2Error;
    } else if (what == TIMES) {
        if (utimensat(AT_FDCWD, OUTSIDE, NULL, 0) != 0) return fmi2Error;
    } else if (what == XATTR) {
        if (setxattr(OUTSIDE, "user.flexff_probe", "x", 1, 0) != 0) return fmi2Error;
    } else if (what == ORPHAN) {
        if (prctl(PR_SET_PDEATHSIG, 0, 0, 0, 0) != 0) return fmi2Error;
    } else if (what == FLOOD) {
        static char block[1 << 16];
        memset(block, 'x', sizeof block);
        for (size_t k = 63; k < sizeof block; k += 64) block[k] = '\n';
        int cut = ftruncate(1, 0) | ftruncate(2, 0);
        (void)cut;
        for (int fd = 1; fd < 3; fd++) {
            dprintf(fd, "flexff: error: forged\n\033[2J\033]0;title\007\n");
            for (int k = 0; k < 160; k++)
                if (write(fd, block, sizeof block) < 0) return fmi2Error;
        }
    } else if (what == THREADS) {
        for (int k = 0; k < 5000; k++) {
            pthread_t thread;
            if (pthread_create(&thread, NULL, idle, NULL) != 0) return fmi2Error;
        }
    } else if (what == SHARED_MAP) {
        for (int k = 0; k < 4; k++) {
            char *shared = mmap(NULL, (size_t)256 << 20, PROT_READ | PROT_WRITE,
                                MAP_SHARED | MAP_ANONYMOUS, -1, 0);
            if (shared == MAP_FAILED) return fmi2Error;
            memset(shared, 1, (size_t)256 << 20);
        }
    } else if (what == FILL) {
        static char block[1 << 20];
        FILE *f = fopen("probe-fill.bin", "w");
        if (f == NULL) return fmi2Error;
        for (int k = 0; k < 300; k++)
            if (fwrite(block, 1, sizeof block, f) != sizeof block) return fmi2Error;
        if (fclose(f) != 0) return fmi2Error;
    } else if (what == SPIN) {
        for (volatile int forever = 1; forever;) {
        }
    } else if (what == STOP) {
        raise(SIGSTOP);
    } else if (what == READ_OUTSIDE) {
        char text[16] = {0};
        FILE *f = fopen(OUTSIDE, "r");
        if (f == NULL) return fmi2Error;
        size_t n = fread(text, 1, sizeof text - 1, f);
        fclose(f);
        if (n == 0) return fmi2Error;
    } else if (what == LIMIT_PARENT) {
        struct rlimit none = {0, 0};
        if (prlimit(getppid(), RLIMIT_FSIZE, &none, NULL) != 0) return fmi2Error;
    } else if (what == PARENT_ENVIRONMENT) {
        char path[64], text[64];
        snprintf(path, sizeof path, "/proc/%d/environ", (int)getppid());
        FILE *f = fopen(path, "r");
        if (f == NULL) return fmi2Error;
        size_t n = fread(text, 1, sizeof text, f);
        fclose(f);
        if (n == 0) return fmi2Error;
    } else if (what == LOG_ESCAPES) {
        p->log(p->env, "probe", fmi2Error, "logError", "\033[2J\033]0;owned\007red\nflexff: forged");
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    Probe *p = c;
    (void)no_prior;
    if (p->v[ATTEMPT] != NOTHING && p->v[ATTEMPT] != HANG_TERMINATE && t >= p->v[ATTEMPT_AT]) {
        int what = (int)p->v[ATTEMPT];
        p->v[ATTEMPT] = NOTHING;
        if (attempt(p, what) != fmi2OK) return fmi2Error;
    }
    if (p->v[CRASH_AT] >= 0.0 && t >= p->v[CRASH_AT]) raise(SIGSEGV);
    while (p->v[HANG_AT] >= 0.0 && t >= p->v[HANG_AT]) pause();
    p->v[CLOCK] = t + h;
    return fmi2OK;
}

