/* QEMU TCG plugin (plugin API v1, QEMU 7.2 as Debian ships it): a profile of the guest's
 * executed instructions by address, over a window between calls of a marker function.
 * The firmware's `cost-marks` feature calls `pe_cost_mark` six times a step (see
 * pe-firmware/src/runtime/marks.rs): the calls are numbered 0, 1, 2, ... and call k opens
 * stage k % period of the step (0 positions, 1 candidate search, 2 travel check, 3 tool
 * tests, 4 pair tests, 5 the rest of the step). `window=S` counts stage S only,
 * `window=all` stages 0 to 4 (the contact evaluation). At exit it writes one line per
 * executed address, "pc ADDR COUNT", through QEMU's log (`-d plugin -D FILE`).
 * scripts/firmware-profile.sh builds and runs it; the prototypes are those of
 * ../shared/tools/insncount/insncount.c (Debian ships no qemu-plugin.h).
 * Build: gcc -O2 -shared -fPIC -fvisibility=hidden -o libpcprofile.so pcprofile.c */
#include <inttypes.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef uint64_t qemu_plugin_id_t;
typedef struct qemu_info_t qemu_info_t;
struct qemu_plugin_tb;
struct qemu_plugin_insn;
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_CB_R_REGS, QEMU_PLUGIN_CB_RW_REGS };
typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void *userdata);
typedef void (*qemu_plugin_vcpu_udata_cb_t)(unsigned int vcpu_index, void *userdata);
typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);

void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn, qemu_plugin_vcpu_udata_cb_t cb,
                                            enum qemu_plugin_cb_flags flags, void *userdata);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void *userdata);
void qemu_plugin_outs(const char *string);

__attribute__((visibility("default"))) int qemu_plugin_version = 1;

/* Thumb code in the first 4 MiB (flash): one counter per halfword address. */
#define SLOTS (1u << 21)
static uint64_t *hist;
static uint64_t mark_addr;
static unsigned mark_no, period = 6;
static int window = 4; /* -1: stages 0 to 4 */
static int active;     /* single vCPU: no atomics needed */

static void on_mark(unsigned int vcpu, void *udata)
{
    int stage = (int)(mark_no++ % period);
    active = window < 0 ? stage < 5 : stage == window;
}

static void on_insn(unsigned int vcpu, void *udata)
{
    if (active)
        hist[((uintptr_t)udata >> 1) & (SLOTS - 1)]++;
}

static void on_tb(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t pc = qemu_plugin_insn_vaddr(insn);
        if (mark_addr && pc == mark_addr)
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_mark, QEMU_PLUGIN_CB_NO_REGS, NULL);
        qemu_plugin_register_vcpu_insn_exec_cb(insn, on_insn, QEMU_PLUGIN_CB_NO_REGS,
                                               (void *)(uintptr_t)pc);
    }
}

static void on_plugin_exit(qemu_plugin_id_t id, void *p)
{
    char buf[64];
    snprintf(buf, sizeof buf, "marks %u\n", mark_no);
    qemu_plugin_outs(buf);
    for (unsigned i = 0; i < SLOTS; i++)
        if (hist[i]) {
            snprintf(buf, sizeof buf, "pc %x %" PRIu64 "\n", i << 1, hist[i]);
            qemu_plugin_outs(buf);
        }
}

__attribute__((visibility("default")))
int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv)
{
    hist = calloc(SLOTS, sizeof *hist);
    if (!hist)
        return -1;
    for (int i = 0; i < argc; i++) {
        if (strncmp(argv[i], "mark=", 5) == 0)
            mark_addr = strtoull(argv[i] + 5, NULL, 0) & ~1ULL; /* drop the Thumb bit */
        else if (strcmp(argv[i], "window=all") == 0)
            window = -1;
        else if (strncmp(argv[i], "window=", 7) == 0)
            window = atoi(argv[i] + 7);
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_tb);
    qemu_plugin_register_atexit_cb(id, on_plugin_exit, NULL);
    return 0;
}
