/* slipest_emu: the estimator firmware main loop on Linux.
 *
 *   slipest_emu --port /dev/pts/N --link slcan|cobs   serve a tty (raw mode)
 *   slipest_emu --stdio --link slcan|cobs             serve stdin/stdout
 *   slipest_emu --pty --link slcan|cobs               open a pty pair, print "PTY <path>"
 *   slipest_emu --vectors vectors.bin [--f32-tol T] [--verbose]   batch check of a bundle's vectors
 *   --model model.img (any mode)                      serve / check the model of that image instead
 *                                                     of the built-in bundle (no rebuild per bundle)
 *   --nvm FILE [--upload model.img [--activate | --try]] [--confirm] [--rollback] (any mode)
 *                                                     boot from A/B model slots kept in FILE (emu_nvm.c;
 *                                                     the built-in model when no slot is valid), upload
 *                                                     an image into the inactive slot, activate it
 *   --profile canopen [--node-id N] (serving modes)   the CANopen node (slipest_co.h) instead of the plain
 *                                                     DBC profile: NMT, heartbeat, SDO (model upload into
 *                                                     the --nvm slots), PDOs; frames on the same links
 *
 * Frames in, estimate and status frames out (host_tools/slipest.dbc). Non-blocking I/O
 * with an output queue: when the queue is full the loop stops reading input until it
 * drains, so nothing is dropped. Exits on SIGTERM/SIGINT or EOF and prints the counters
 * to stderr.
 */
#define _XOPEN_SOURCE 700
#define _DEFAULT_SOURCE

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <unistd.h>

#include "slipest_bundle.h"
#include "slipest_codec.h"
#include "slipest_image.h"
#if SLIPEST_LAYER_TABLE
#include "slipest_image_table.h"
#endif
#include "slipest_infer.h"
#include "slipest_node.h"
#include "slipest_store.h"
#include "slipest_vectors.h"
#include "emu_nvm.h"
#include "emu_canopen.h"
#ifdef SLIPEST_HMAC_KEY
#include "slipest_hmac_key.h" /* generated from -DSLIPEST_HMAC_KEY_FILE=... */
#endif

#define OUT_QUEUE 65536u
/* stop reading below this: one read chunk can complete ~40 frames of <= 9 x 23 output bytes */
#define OUT_HIGH_WATER (OUT_QUEUE - 16384u)
#define READ_CHUNK 256u

enum link_kind { LINK_SLCAN, LINK_COBS };

typedef struct {
    int in_fd, out_fd;
    enum link_kind link;
    slipest_node_t node;
    slipest_slcan_rx_t slcan;
    slipest_cobs_rx_t cobs;
    uint8_t out[OUT_QUEUE];
    size_t out_head, out_len; /* ring buffer */
} emu_t;

static volatile sig_atomic_t stop_requested = 0;
static int profile_canopen = 0; /* --profile canopen */

/* the model served: the built-in bundle's, or one read from a model image (--model) */
static const slipest_model_q_t *model_q;
static const slipest_model_f32_t *model_f32;
static char model_hex[9]; /* the model's hash32 as text */
static const uint8_t *model_sha256; /* its sha256 content hash (the CANopen node's 0x2001 sub 3) */

/* Read a whole image file into buf (cap bytes: one more than the largest image, so that a longer
 * file reaches the reader and is refused there). Returns 0, or 2 with a message. */
static int read_image_file(const char *path, uint8_t *buf, size_t cap, size_t *n)
{
    FILE *fp = fopen(path, "rb");
    if (fp == NULL) {
        fprintf(stderr, "slipest_emu: cannot open %s: %s\n", path, strerror(errno));
        return 2;
    }
    *n = fread(buf, 1, cap, fp);
    fclose(fp);
    return 0;
}

/* Read a model image file through the validating C reader into static storage (as a flight
 * node would read a received image from its buffer). Returns 0, or 2 with a message. */
static int load_model_image(const char *path)
{
    /* one byte more than the largest image this build reads: a longer file is refused */
#if SLIPEST_LAYER_TABLE
    static uint8_t buf[(SLIPEST_IMAGE_TABLE_MAX_SIZE > SLIPEST_IMAGE_MAX_SIZE ? SLIPEST_IMAGE_TABLE_MAX_SIZE
                                                                              : SLIPEST_IMAGE_MAX_SIZE) + 1u];
    static slipest_image_table_q_t tqs; /* format 2: the layer table */
    static slipest_image_table_f32_t tfs;
#else
    static uint8_t buf[SLIPEST_IMAGE_MAX_SIZE + 1u]; /* format 1 only: format 2 is refused by its version */
#endif
    static slipest_image_q_storage_t qs;
    static slipest_image_f32_storage_t fs;
    static slipest_model_q_t mq;
    static slipest_model_f32_t mf;
    size_t n = 0;
    int st;
    if (read_image_file(path, buf, sizeof buf, &n) != 0) {
        return 2;
    }
#if SLIPEST_LAYER_TABLE
    if (slipest_image_format_of(buf, n) == SLIPEST_IMAGE_V2_FORMAT) {
        st = slipest_image_read_table(buf, n, 0u, &mq, &tqs, &mf, &tfs);
    } else
#endif
    {
        st = slipest_image_read(buf, n, 0u, &mq, &qs, &mf, &fs);
    }
    if (st != SLIPEST_OK) {
        fprintf(stderr, "slipest_emu: %s: model image rejected: %s (%d)\n", path, slipest_status_str(st), st);
        return 2;
    }
    model_q = &mq;
    model_f32 = &mf;
    { /* the image's trailer (before the HMAC tag, when it has one) carries the sha256 content hash */
        static uint8_t sha[32];
        unsigned flags = (unsigned)buf[SLIPEST_IMAGE_OFF_FLAGS] | ((unsigned)buf[SLIPEST_IMAGE_OFF_FLAGS + 1u] << 8);
        size_t tag = (flags & SLIPEST_IMAGE_FLAG_HMAC) != 0u ? SLIPEST_IMAGE_HMAC_SIZE : 0u;
        memcpy(sha, &buf[n - tag - SLIPEST_IMAGE_TRAILER_SIZE + SLIPEST_IMAGE_TRAILER_OFF_SHA256], sizeof sha);
        model_sha256 = sha;
    }
    snprintf(model_hex, sizeof model_hex, "%08lx", (unsigned long)slipest_model_hash32(model_q));
    return 0;
}

/* --nvm: the model store over a file, as a flight node keeps its slots in flash */
static emu_nvm_t nvm_file;
static slipest_store_t store;

static void use_store_model(void)
{
    if (slipest_store_model_q(&store) == NULL) return; /* no valid slot: the built-in model serves */
    model_q = slipest_store_model_q(&store);
    model_f32 = slipest_store_model_f32(&store);
    snprintf(model_hex, sizeof model_hex, "%08lx", (unsigned long)slipest_model_hash32(model_q));
}

static int open_store(const char *path, uint32_t sector)
{
    slipest_nvm_t nvm;
    const slipest_store_auth_t *auth = NULL;
    int st;
#ifdef SLIPEST_HMAC_KEY
    static const slipest_store_auth_t hmac = SLIPEST_STORE_AUTH_HMAC_SHA256(slipest_hmac_key, sizeof slipest_hmac_key);
    auth = &hmac;
#endif
    if (emu_nvm_open(&nvm_file, path, sector, SLIPEST_STORE_NVM_SECTORS(sector), &nvm) != 0) {
        fprintf(stderr, "slipest_emu: cannot open NVM file %s: %s\n", path, strerror(errno));
        return 2;
    }
    st = slipest_store_open(&store, &nvm, auth);
    if (st != SLIPEST_OK && st != SLIPEST_E_STATE && st != SLIPEST_E_NVM) {
        fprintf(stderr, "slipest_emu: store: %s\n", slipest_status_str(st));
        return 2;
    }
    use_store_model();
    fprintf(stderr, "slipest_emu: store boot: %s, slot %d, model %s version %lu%s\n",
            st == SLIPEST_OK ? "slot model" : "built-in model", slipest_store_active_slot(&store), model_hex,
            (unsigned long)model_q->version,
            slipest_store_trial_state(&store) == SLIPEST_TRIAL_REVERTED ? ", trial reverted"
            : (slipest_store_trial_state(&store) == SLIPEST_TRIAL_RUNNING ? ", on trial" : ""));
    return 0;
}

/* Send an image file through the store in chunks of 7 bytes (as CAN SDO segments would come),
 * then validate it; activate when asked. Returns 0, or 3 with a message when refused. */
static int upload_image(const char *path, int activate)
{
    static uint8_t buf[SLIPEST_STORE_IMAGE_MAX + 1u]; /* a longer file is refused by its length */
    size_t n = 0, off;
    int st;
    if (read_image_file(path, buf, sizeof buf, &n) != 0) {
        return 2;
    }
    st = slipest_store_begin(&store, (uint32_t)n, 0u);
    for (off = 0; st == SLIPEST_OK && off < n; off += 7u) {
        st = slipest_store_write(&store, (uint32_t)off, buf + off, n - off < 7u ? n - off : 7u);
    }
    if (st == SLIPEST_OK) st = slipest_store_finish(&store);
    if (st == SLIPEST_OK && activate) st = (activate == 2) ? slipest_store_try(&store) : slipest_store_activate(&store);
    if (st != SLIPEST_OK) {
        fprintf(stderr, "slipest_emu: upload refused: %s (%d)\n", slipest_status_str(st), st);
        return 3;
    }
    use_store_model();
    fprintf(stderr, "slipest_emu: upload ok%s: slot %d, model %s version %lu\n",
            activate == 2 ? ", on trial" : (activate ? ", activated" : ""),
            slipest_store_active_slot(&store), model_hex, (unsigned long)model_q->version);
    return 0;
}

static void on_signal(int sig)
{
    (void)sig;
    stop_requested = 1;
}

static void queue_bytes(emu_t *e, const void *data, size_t n)
{
    const uint8_t *p = data;
    size_t i;
    /* callers keep out_len below OUT_HIGH_WATER before feeding more input */
    for (i = 0; i < n && e->out_len < OUT_QUEUE; i++) {
        e->out[(e->out_head + e->out_len) % OUT_QUEUE] = p[i];
        e->out_len++;
    }
}

static void queue_frames(emu_t *e, const slipest_frame_t *f, int n)
{
    int i;
    for (i = 0; i < n; i++) {
        uint8_t buf[40];
        int len = e->link == LINK_SLCAN ? slipest_slcan_format(&f[i], (char *)buf, sizeof buf)
                                        : slipest_cobs_format(&f[i], buf, sizeof buf);
        if (len > 0) queue_bytes(e, buf, (size_t)len);
    }
}

static void handle_frame(emu_t *e, const slipest_frame_t *in)
{
    slipest_frame_t out[SLIPEST_NODE_MAX_OUT > SLIPEST_CO_MAX_OUT ? SLIPEST_NODE_MAX_OUT : SLIPEST_CO_MAX_OUT];
    int n = profile_canopen ? emu_co_handle(in, out, SLIPEST_CO_MAX_OUT)
                            : slipest_node_handle(&e->node, in, out, SLIPEST_NODE_MAX_OUT);
    if (n > 0) queue_frames(e, out, n);
}

static void feed_byte(emu_t *e, uint8_t b)
{
    slipest_frame_t f;
    int r;
    if (e->link == LINK_SLCAN) {
        char reply[SLIPEST_SLCAN_REPLY_MAX];
        size_t reply_len = 0;
        r = slipest_slcan_rx_feed(&e->slcan, b, &f, reply, &reply_len);
        if (r == SLIPEST_SLCAN_FRAME) handle_frame(e, &f);
        else if (r < 0) slipest_node_link_error(&e->node);
        if (reply_len > 0) queue_bytes(e, reply, reply_len);
    } else {
        r = slipest_cobs_rx_feed(&e->cobs, b, &f);
        if (r == 1) handle_frame(e, &f);
        else if (r < 0) slipest_node_link_error(&e->node);
    }
}

/* write as much of the queue as the fd takes now; -1 on a fatal error */
static int flush_some(emu_t *e)
{
    while (e->out_len > 0) {
        size_t chunk = e->out_len;
        ssize_t w;
        if (e->out_head + chunk > OUT_QUEUE) chunk = OUT_QUEUE - e->out_head;
        w = write(e->out_fd, e->out + e->out_head, chunk);
        if (w < 0) {
            if (errno == EINTR) continue;
            if (errno == EAGAIN || errno == EWOULDBLOCK) return 0;
            return -1;
        }
        e->out_head = (e->out_head + (size_t)w) % OUT_QUEUE;
        e->out_len -= (size_t)w;
    }
    return 0;
}

static int set_raw_nonblock(int fd)
{
    struct termios t;
    int flags;
    if (isatty(fd)) {
        if (tcgetattr(fd, &t) != 0) return -1;
        cfmakeraw(&t);
        t.c_cc[VMIN] = 1;
        t.c_cc[VTIME] = 0;
        if (tcsetattr(fd, TCSANOW, &t) != 0) return -1;
    }
    flags = fcntl(fd, F_GETFL);
    if (flags < 0 || fcntl(fd, F_SETFL, flags | O_NONBLOCK) != 0) return -1;
    return 0;
}

static int serve(emu_t *e)
{
    int eof = 0;
    while (!stop_requested && !(eof && e->out_len == 0)) {
        struct pollfd p[2];
        int np = 0, in_idx = -1, out_idx = -1, r;
        if (!eof && e->out_len < OUT_HIGH_WATER) {
            p[np].fd = e->in_fd;
            p[np].events = POLLIN;
            in_idx = np++;
        }
        if (e->out_len > 0) {
            if (e->out_fd == e->in_fd && in_idx >= 0) {
                p[in_idx].events |= POLLOUT;
                out_idx = in_idx;
            } else {
                p[np].fd = e->out_fd;
                p[np].events = POLLOUT;
                out_idx = np++;
            }
        }
        r = poll(p, (nfds_t)np, profile_canopen ? 2 : 200); /* CANopen: a 2 ms tick for heartbeat/timeouts */
        if (r < 0) {
            if (errno == EINTR) continue;
            perror("slipest_emu: poll");
            return 1;
        }
        if (profile_canopen) {
            slipest_frame_t t[SLIPEST_CO_MAX_OUT]; /* heartbeat, SDO timeout, or the segments of a block upload */
            queue_frames(e, t, emu_co_tick(t, SLIPEST_CO_MAX_OUT));
        }
        if (out_idx >= 0 && (p[out_idx].revents & (POLLOUT | POLLERR))) {
            if (flush_some(e) != 0) {
                if (errno == EIO || errno == EPIPE) return 0; /* peer went away */
                perror("slipest_emu: write");
                return 1;
            }
        }
        if (in_idx >= 0 && (p[in_idx].revents & (POLLIN | POLLHUP | POLLERR))) {
            uint8_t buf[READ_CHUNK];
            ssize_t n = read(e->in_fd, buf, sizeof buf);
            if (n > 0) {
                ssize_t i;
                for (i = 0; i < n; i++) feed_byte(e, buf[i]);
                if (flush_some(e) != 0 && errno != EAGAIN) return errno == EIO ? 0 : 1;
            } else if (n == 0 || (errno != EAGAIN && errno != EINTR && errno != EWOULDBLOCK)) {
                eof = 1; /* EOF, or EIO when the other side of a pty closed */
                if (e->out_fd == e->in_fd) return 0;
            }
        }
    }
    return 0;
}

static void print_counters(const emu_t *e)
{
    slipest_counters_t c;
    slipest_node_counters(&e->node, &c);
    fprintf(stderr,
            "slipest_emu: frames_received=%lu frames_rejected=%lu samples_dropped=%lu windows_flagged=%lu "
            "windows_done=%lu saturations=%lu\n",
            (unsigned long)c.frames_received, (unsigned long)c.frames_rejected, (unsigned long)c.samples_dropped,
            (unsigned long)c.windows_flagged, (unsigned long)c.windows_done, (unsigned long)c.saturations);
}

/* The float check's tolerance, |f32 - torch| <= tol * max(1, |torch logit|): by default the built bundle's
 * manifest.json float_tolerance (CMake passes it), --f32-tol for the vectors of another bundle. */
#ifndef SLIPEST_BUNDLE_F32_TOL
#error "SLIPEST_BUNDLE_F32_TOL: the bundle's float tolerance (manifest.json float_tolerance), set by CMakeLists.txt"
#endif

static int run_vectors(const char *path, float tol, int verbose)
{
    FILE *fp = fopen(path, "rb");
    uint8_t *buf;
    long size;
    slipest_vectors_t v;
    const char *why = "";
    uint32_t i, q_fail = 0, f_fail = 0;
    if (fp == NULL) {
        fprintf(stderr, "slipest_emu: cannot open %s: %s\n", path, strerror(errno));
        return 2;
    }
    if (fseek(fp, 0, SEEK_END) != 0 || (size = ftell(fp)) < 0 || fseek(fp, 0, SEEK_SET) != 0) {
        fprintf(stderr, "slipest_emu: cannot size %s\n", path);
        fclose(fp);
        return 2;
    }
    buf = malloc(size > 0 ? (size_t)size : 1u);
    if (buf == NULL || fread(buf, 1, (size_t)size, fp) != (size_t)size) {
        fprintf(stderr, "slipest_emu: cannot read %s\n", path);
        free(buf);
        fclose(fp);
        return 2;
    }
    fclose(fp);
    if (slipest_vectors_parse(buf, (size_t)size, &v, &why) != 0) {
        fprintf(stderr, "slipest_emu: %s: %s\n", path, why);
        free(buf);
        return 2;
    }
    for (i = 0; i < v.n; i++) {
        int32_t q[3];
        float f[3];
        int fq = slipest_vectors_check_q(&v, model_q, i, q);
        int ff = slipest_vectors_check_f32(&v, model_f32, i, tol, f);
        q_fail += fq != 0;
        f_fail += ff != 0;
        if (verbose)
            printf("%lu q_class=%d q_logits=%ld,%ld,%ld f32_logits=%.9g,%.9g,%.9g q_fail=%d f32_fail=%d %s\n",
                   (unsigned long)i,
                   q[1] > q[0] ? (q[2] > q[1] ? 2 : 1) : (q[2] > q[0] ? 2 : 0), (long)q[0], (long)q[1], (long)q[2], (double)f[0], (double)f[1], (double)f[2],
                   fq, ff, (fq | ff) ? "FAIL" : "ok");
    }
    printf("vectors=%lu q_exact=%lu f32_within_tol=%lu f32_tol=%.3g model_hash=%s %s\n", (unsigned long)v.n,
           (unsigned long)(v.n - q_fail), (unsigned long)(v.n - f_fail), (double)tol, model_hex,
           (q_fail == 0 && f_fail == 0) ? "PASS" : "FAIL");
    free(buf);
    return (q_fail == 0 && f_fail == 0) ? 0 : 1;
}

static void usage(FILE *to)
{
    fprintf(to,
            "usage: slipest_emu (--port TTY | --stdio | --pty) [--link slcan|cobs]\n"
            "       slipest_emu --vectors vectors.bin [--f32-tol T] [--verbose]\n"
            "  --port TTY     serve a serial device / pty slave (set to raw mode)\n"
            "  --stdio        serve stdin/stdout\n"
            "  --pty          create a pseudo-terminal and print 'PTY <slave path>' on stdout\n"
            "  --link KIND    slcan (ASCII tIIILDD..\\r, default) or cobs (COBS + CRC-16 packets)\n"
            "  --model IMG    use the model of a model image (model.img) instead of the built-in bundle\n"
            "  --vectors F    check every test vector (fixed-point logits exact, float within T*max(1,|logit|))\n"
            "  --f32-tol T    the float tolerance of those vectors' bundle (manifest.json float_tolerance.tolerance;\n"
            "                 default: the built-in bundle's)\n"
            "  --version      print library version and model hash\n"
            "  --profile P    dbc (the plain profile, default) or canopen (CANopen node, see slipest_co.h)\n"
            "  --node-id N    CANopen node id, 1..127 (default 5)\n"
            "  --nvm FILE     boot from the A/B model slots in FILE (created erased when absent)\n"
            "  --nvm-sector N NVM sector size of FILE (default 256)\n"
            "  --upload IMG   write a model image into the inactive slot and validate it (needs --nvm)\n"
            "  --activate     activate the uploaded image; --rollback: re-activate the previous slot\n"
            "  --try          activate the uploaded image on trial: the next boot reverts it unless --confirm\n"
            "  --confirm      confirm the model on trial (the store's commit record)\n"
            "  test hook: --nvm-cut-after K [--nvm-cut-mode before|torn|after] dies by SIGKILL inside the\n"
            "             K-th NVM write/erase (before it, after half a sector, or after all of it)\n");
}

int main(int argc, char **argv)
{
    static emu_t e; /* 64 KB queue: not on the stack */
    const char *port = NULL, *vectors = NULL, *nvm_path = NULL, *upload = NULL;
    int use_stdio = 0, use_pty = 0, verbose = 0, i, rc, slave_keep = -1, activate = 0, rollback = 0, confirm = 0;
    int print_version = 0;
    const slipest_model_q_t *boot_q;
    const slipest_model_f32_t *boot_f;
    const uint8_t *boot_sha256;
    unsigned long sector = 256ul, cut_after = 0ul, node_id = 5ul;
    int cut_mode = EMU_CUT_BEFORE;
    float f32_tol = (float)(SLIPEST_BUNDLE_F32_TOL);
    struct sigaction sa;

    e.link = LINK_SLCAN;
    model_q = slipest_bundle_model_q();
    model_f32 = slipest_bundle_model_f32();
    model_sha256 = slipest_bundle_sha256();
    snprintf(model_hex, sizeof model_hex, "%08lx", (unsigned long)slipest_model_hash32(model_q));
    for (i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--port") == 0 && i + 1 < argc) port = argv[++i];
        else if (strcmp(argv[i], "--stdio") == 0) use_stdio = 1;
        else if (strcmp(argv[i], "--pty") == 0) use_pty = 1;
        else if (strcmp(argv[i], "--vectors") == 0 && i + 1 < argc) vectors = argv[++i];
        else if (strcmp(argv[i], "--verbose") == 0) verbose = 1;
        else if (strcmp(argv[i], "--f32-tol") == 0 && i + 1 < argc) {
            char *end = NULL;
            double t = strtod(argv[++i], &end);
            if (end == argv[i] || *end != '\0' || !(t > 0.0) || !(t < 1.0)) {
                fprintf(stderr, "slipest_emu: --f32-tol needs a number in (0, 1), got '%s'\n", argv[i]);
                return 2;
            }
            f32_tol = (float)t;
        }
        else if (strcmp(argv[i], "--nvm") == 0 && i + 1 < argc) nvm_path = argv[++i];
        else if (strcmp(argv[i], "--nvm-sector") == 0 && i + 1 < argc) sector = strtoul(argv[++i], NULL, 10);
        else if (strcmp(argv[i], "--nvm-cut-after") == 0 && i + 1 < argc) cut_after = strtoul(argv[++i], NULL, 10);
        else if (strcmp(argv[i], "--nvm-cut-mode") == 0 && i + 1 < argc) {
            const char *m = argv[++i];
            if (strcmp(m, "before") == 0) cut_mode = EMU_CUT_BEFORE;
            else if (strcmp(m, "torn") == 0) cut_mode = EMU_CUT_TORN;
            else if (strcmp(m, "after") == 0) cut_mode = EMU_CUT_AFTER;
            else {
                fprintf(stderr, "slipest_emu: unknown --nvm-cut-mode '%s' (before, torn, after)\n", m);
                return 2;
            }
        }
        else if (strcmp(argv[i], "--upload") == 0 && i + 1 < argc) upload = argv[++i];
        else if (strcmp(argv[i], "--activate") == 0) activate = 1;
        else if (strcmp(argv[i], "--try") == 0) activate = 2;
        else if (strcmp(argv[i], "--confirm") == 0) confirm = 1;
        else if (strcmp(argv[i], "--rollback") == 0) rollback = 1;
        else if (strcmp(argv[i], "--profile") == 0 && i + 1 < argc) {
            const char *k = argv[++i];
            if (strcmp(k, "canopen") == 0) profile_canopen = 1;
            else if (strcmp(k, "dbc") != 0) {
                fprintf(stderr, "slipest_emu: unknown profile '%s' (dbc or canopen)\n", k);
                return 2;
            }
        } else if (strcmp(argv[i], "--node-id") == 0 && i + 1 < argc) {
            node_id = strtoul(argv[++i], NULL, 10);
            if (node_id < 1ul || node_id > 127ul) {
                fprintf(stderr, "slipest_emu: --node-id must be 1..127\n");
                return 2;
            }
        }
        else if (strcmp(argv[i], "--model") == 0 && i + 1 < argc) {
            if (load_model_image(argv[++i]) != 0) return 2;
        }
        else if (strcmp(argv[i], "--link") == 0 && i + 1 < argc) {
            const char *k = argv[++i];
            if (strcmp(k, "slcan") == 0) e.link = LINK_SLCAN;
            else if (strcmp(k, "cobs") == 0) e.link = LINK_COBS;
            else {
                fprintf(stderr, "slipest_emu: unknown link '%s' (slcan or cobs)\n", k);
                return 2;
            }
        } else if (strcmp(argv[i], "--version") == 0) {
            print_version = 1;
        } else if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) {
            usage(stdout);
            return 0;
        } else {
            fprintf(stderr, "slipest_emu: bad argument '%s'\n", argv[i]);
            usage(stderr);
            return 2;
        }
    }
    boot_q = model_q; /* the built-in (or --model) model, before a slot's replaces it */
    boot_sha256 = model_sha256;
    boot_f = model_f32;
    if (nvm_path != NULL) {
        if (sector < SLIPEST_STORE_SECTOR_MIN || sector > SLIPEST_STORE_SECTOR_MAX) {
            fprintf(stderr, "slipest_emu: --nvm-sector %lu outside %u..%u\n", sector, SLIPEST_STORE_SECTOR_MIN,
                    SLIPEST_STORE_SECTOR_MAX);
            return 2;
        }
        /* armed before the boot: the hook cuts the revert of a model on trial that the boot makes (the only NVM
         * write a boot can make), then an upload/activation/confirm/rollback */
        nvm_file.cut_after = (uint32_t)cut_after;
        nvm_file.mode = cut_mode;
        rc = open_store(nvm_path, (uint32_t)sector);
        if (rc != 0) return rc;
        if (upload != NULL && (rc = upload_image(upload, activate)) != 0) return rc;
        if (confirm) {
            rc = slipest_store_confirm(&store);
            if (rc != SLIPEST_OK) {
                fprintf(stderr, "slipest_emu: confirm refused: %s (%d)\n", rc == SLIPEST_E_STATE ? "no model on trial"
                                : slipest_status_str(rc), rc);
                return 3;
            }
            fprintf(stderr, "slipest_emu: confirmed: slot %d, model %s\n", slipest_store_active_slot(&store), model_hex);
        }
        if (rollback) {
            rc = slipest_store_rollback(&store);
            if (rc == SLIPEST_E_STATE) {
                fprintf(stderr, "slipest_emu: rollback refused: no previous model (none was active before this one, "
                                "or an upload since has taken its slot)\n");
                return 3;
            }
            if (rc != SLIPEST_OK) {
                fprintf(stderr, "slipest_emu: rollback refused: %s (%d)\n", slipest_status_str(rc), rc);
                return 3;
            }
            use_store_model();
            fprintf(stderr, "slipest_emu: rollback ok: slot %d, model %s version %lu\n",
                    slipest_store_active_slot(&store), model_hex, (unsigned long)model_q->version);
        }
        fprintf(stderr, "slipest_emu: nvm ops=%lu\n", (unsigned long)nvm_file.ops);
    } else if (upload != NULL || rollback || confirm) {
        fprintf(stderr, "slipest_emu: --upload / --rollback / --confirm need --nvm FILE\n");
        return 2;
    }
    if (print_version) {
        printf("slipest %u.%u model %s version %lu\n", slipest_lib_version() >> 8, slipest_lib_version() & 0xFFu,
               model_hex, (unsigned long)model_q->version);
        return 0;
    }
    if (vectors != NULL) return run_vectors(vectors, f32_tol, verbose);
    if (nvm_path != NULL && port == NULL && !use_stdio && !use_pty) return 0; /* store operations only */
    if ((port != NULL) + use_stdio + use_pty != 1) {
        usage(stderr);
        return 2;
    }

    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);

    rc = slipest_node_init(&e.node, model_q, model_f32);
    if (rc != SLIPEST_OK) {
        fprintf(stderr, "slipest_emu: model rejected: %s\n", slipest_status_str(rc));
        return 2;
    }
    slipest_slcan_rx_init(&e.slcan);
    slipest_cobs_rx_init(&e.cobs);
    if (use_stdio) {
        e.in_fd = STDIN_FILENO;
        e.out_fd = STDOUT_FILENO;
        if (set_raw_nonblock(e.in_fd) != 0 || set_raw_nonblock(e.out_fd) != 0) {
            perror("slipest_emu: stdio");
            return 1;
        }
    } else if (use_pty) {
        int m = posix_openpt(O_RDWR | O_NOCTTY);
        const char *name;
        if (m < 0 || grantpt(m) != 0 || unlockpt(m) != 0 || (name = ptsname(m)) == NULL) {
            perror("slipest_emu: pty");
            return 1;
        }
        /* keep a slave fd open so the master does not see a hang-up between host opens */
        slave_keep = open(name, O_RDWR | O_NOCTTY);
        if (slave_keep < 0 || set_raw_nonblock(slave_keep) != 0) {
            perror("slipest_emu: pty slave");
            return 1;
        }
        printf("PTY %s\n", name);
        fflush(stdout);
        e.in_fd = e.out_fd = m;
        if (set_raw_nonblock(m) != 0) {
            perror("slipest_emu: pty master");
            return 1;
        }
    } else {
        int fd = open(port, O_RDWR | O_NOCTTY | O_NONBLOCK);
        if (fd < 0) {
            fprintf(stderr, "slipest_emu: cannot open %s: %s\n", port, strerror(errno));
            return 1;
        }
        if (set_raw_nonblock(fd) != 0) {
            fprintf(stderr, "slipest_emu: cannot configure %s: %s\n", port, strerror(errno));
            return 1;
        }
        e.in_fd = e.out_fd = fd;
    }
    if (profile_canopen) {
        slipest_frame_t boot[3]; /* boot-up, the no-model EMCY, the trial-reverted EMCY */
        rc = emu_co_start((uint8_t)node_id, nvm_path != NULL ? &store : NULL, boot_q, boot_f, boot_sha256, boot, 3u);
        if (rc < 0) {
            fprintf(stderr, "slipest_emu: CANopen node: %s\n", slipest_status_str(rc));
            return 2;
        }
        queue_frames(&e, boot, rc); /* the boot-up message and its EMCYs */
    }
    fprintf(stderr, "slipest_emu: ready link=%s profile=%s model=%s lib=%u.%u\n",
            e.link == LINK_SLCAN ? "slcan" : "cobs", profile_canopen ? "canopen" : "dbc", model_hex,
            slipest_lib_version() >> 8, slipest_lib_version() & 0xFFu);
    rc = serve(&e);
    if (profile_canopen) emu_co_print_counters();
    else print_counters(&e);
    if (slave_keep >= 0) close(slave_keep);
    return rc;
}
