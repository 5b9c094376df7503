/*
 * paced_floor: a loop paced exactly like the twin's stepping thread, doing no work.
 *
 * Absolute deadlines t0 + k * period on CLOCK_MONOTONIC; before each deadline the loop sleeps
 * with clock_nanosleep(TIMER_ABSTIME) to SPIN_NS before it, then spins to the deadline; a step
 * that ends after its deadline is an overrun and the late steps run back to back (no skipping),
 * as the twin's pacer does. Under SCHED_FIFO when permitted; like the twin's pacer, it holds a
 * request for zero CPU wake-up latency (/dev/cpu_dma_latency) when the environment sets
 * CONVEYOR_TWIN_CPU_LATENCY_REQUEST=1 and the device is writable. Whatever overruns this loop sees, no
 * 1 kHz loop on the machine can avoid: it is the host's floor.
 *
 * With WORK_NS > 0 each step, once its deadline is reached, does a fixed amount of computation
 * (passes over a 128 kB array, calibrated before the loop to take WORK_NS at the median), as the
 * twin's step does: a CPU that runs slower for a while makes that work late, which a loop doing
 * no work never notices. Steps whose work took more than 1.5 times the calibrated time are
 * counted (slow_work).
 *
 * usage: paced_floor SECONDS [PERIOD_NS] [FIFO_PRIORITY] [WORK_NS]
 * prints one JSON object: steps, overruns, max lateness [ns], wake-ups later than the spin
 * margin, the scheduling policy and the latency request obtained, the work per step.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define SLEEP_MIN_NS 200000LL /* sleep only when the deadline is further than this [ns] */
#define SPIN_NS 150000LL      /* wake this long before the deadline, then spin [ns] */
#define WORK_LEN 16384        /* doubles in the work array (128 kB) */
#define CALIBRATION_TRIALS 301

static double work_array[WORK_LEN];
static volatile double work_sink;

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void sleep_until(int64_t t)
{
    struct timespec ts = {.tv_sec = t / 1000000000LL, .tv_nsec = t % 1000000000LL};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
    }
}

/* The step's work: `passes` passes over the work array, each depending on the one before. */
static void work(int64_t passes)
{
    double acc = work_sink;
    for (int64_t p = 0; p < passes; p++)
        for (int i = 0; i < WORK_LEN; i++) {
            acc += work_array[i];
            work_array[i] = acc * 1e-9;
        }
    work_sink = acc;
}

static int compare_i64(const void *a, const void *b)
{
    int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* The median time of one pass [ns]. */
static int64_t pass_ns(void)
{
    int64_t t[CALIBRATION_TRIALS];
    for (int k = 0; k < CALIBRATION_TRIALS; k++) {
        int64_t t0 = now_ns();
        work(1);
        t[k] = now_ns() - t0;
    }
    qsort(t, CALIBRATION_TRIALS, sizeof t[0], compare_i64);
    return t[CALIBRATION_TRIALS / 2] > 0 ? t[CALIBRATION_TRIALS / 2] : 1;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: paced_floor SECONDS [PERIOD_NS] [FIFO_PRIORITY] [WORK_NS]\n");
        return 2;
    }
    double seconds = atof(argv[1]);
    int64_t period = argc > 2 ? atoll(argv[2]) : 1000000LL;
    int priority = argc > 3 ? atoi(argv[3]) : 10;
    int64_t work_ns = argc > 4 ? atoll(argv[4]) : 0;
    if (seconds <= 0 || period <= 0 || work_ns < 0 || work_ns >= period) {
        fprintf(stderr, "paced_floor: SECONDS and PERIOD_NS must be positive, WORK_NS in "
                        "[0, PERIOD_NS)\n");
        return 2;
    }
    const char *policy = "normal";
    if (priority > 0) {
        struct sched_param param = {.sched_priority = priority};
        policy = sched_setscheduler(0, SCHED_FIFO, &param) == 0 ? "SCHED_FIFO" :
                 "normal (SCHED_FIFO refused)";
    }
    const char *latency = "off";
    const char *setting = getenv("CONVEYOR_TWIN_CPU_LATENCY_REQUEST");
    if (setting && strcmp(setting, "1") == 0) {
        int fd = open("/dev/cpu_dma_latency", O_WRONLY); /* held until the process ends */
        int32_t zero = 0;
        latency = fd >= 0 && write(fd, &zero, sizeof zero) == sizeof zero ? "held" : "refused";
    }
    int64_t passes = 0, work_calibrated = 0, slow_work = 0;
    if (work_ns > 0) {
        int64_t one = pass_ns();
        passes = (work_ns + one / 2) / one > 0 ? (work_ns + one / 2) / one : 1;
        work_calibrated = passes * one;
    }
    int64_t steps = (int64_t)(seconds * 1e9 / (double)period);
    int64_t overruns = 0, late_wakes = 0, max_lateness = 0;
    int64_t start = now_ns();
    for (int64_t k = 1; k <= steps; k++) {
        int64_t deadline = start + k * period;
        int64_t t = now_ns();
        if (t > deadline) {
            overruns++;
            if (t - deadline > max_lateness)
                max_lateness = t - deadline;
            continue;
        }
        if (deadline - t > SLEEP_MIN_NS) {
            sleep_until(deadline - SPIN_NS);
            if (now_ns() > deadline)
                late_wakes++;
        }
        while (now_ns() < deadline) {
        }
        if (passes) {
            int64_t t0 = now_ns();
            work(passes);
            if (2 * (now_ns() - t0) > 3 * work_calibrated)
                slow_work++;
        }
    }
    printf("{\"steps\": %lld, \"overruns\": %lld, \"max_lateness_ns\": %lld, "
           "\"late_wakes\": %lld, \"period_ns\": %lld, \"policy\": \"%s\", "
           "\"latency_request\": \"%s\", \"work_ns\": %lld, \"work_passes\": %lld, "
           "\"slow_work\": %lld}\n",
           (long long)steps, (long long)overruns, (long long)max_lateness,
           (long long)late_wakes, (long long)period, policy, latency,
           (long long)work_calibrated, (long long)passes, (long long)slow_work);
    return 0;
}
