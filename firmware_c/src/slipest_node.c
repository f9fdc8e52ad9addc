/* Estimator node: frame dispatch, sample assembly, windows -> inference -> output frames. */
#include "slipest_node.h"

#include <string.h>

#include "slipest_dbc.h"
#include "slipest_infer.h"
#include "slipest_node_internal.h"

#define TELEM_ALL 0x07u
#define FEATURES_ALL 0x0Fu
#define CLASS_NONE 255u

slipest_status_t slipest_node_init(slipest_node_t *node, const slipest_model_q_t *mq, const slipest_model_f32_t *mf)
{
    slipest_status_t st;
    if (node == NULL) return SLIPEST_E_NULL;
    st = slipest_node_check_models(mq, mf);
    if (st != SLIPEST_OK) return st;
    memset(node, 0, sizeof *node);
    node->mq = mq;
    node->mf = mf;
    return slipest_extractor_init(&node->ex);
}

uint16_t slipest_lib_version(void) { return SLIPEST_LIB_VERSION; }
size_t slipest_node_size(void) { return sizeof(slipest_node_t); }
size_t slipest_frame_size(void) { return sizeof(slipest_frame_t); }

/* SLIPEST_NODE_MAX_OUT as a value, so ctypes callers size their output buffer from the library. */
size_t slipest_node_max_out(void) { return (size_t)SLIPEST_NODE_MAX_OUT; }

static int reject(slipest_node_t *node, int status)
{
    node->c.frames_rejected++;
    return status;
}

slipest_status_t slipest_node_link_error(slipest_node_t *node)
{
    if (node == NULL) return SLIPEST_E_NULL;
    node->c.frames_received++;
    node->c.frames_rejected++;
    node->link_rejected++;
    return SLIPEST_OK;
}

static void sync_counters(slipest_node_t *node)
{
    node->c.samples_dropped = node->ex.samples_dropped;
    node->c.windows_flagged = node->ex.windows_flagged;
}

slipest_status_t slipest_node_counters(const slipest_node_t *node, slipest_counters_t *out)
{
    if (node == NULL || out == NULL) return SLIPEST_E_NULL;
    *out = node->c;
    out->samples_dropped = node->ex.samples_dropped;
    out->windows_flagged = node->ex.windows_flagged;
    return SLIPEST_OK;
}

int slipest_node_status(const slipest_node_t *node, slipest_frame_t *out, size_t cap)
{
    struct slipest_dbc_status_model_t m;
    struct slipest_dbc_status_rx_t rx;
    struct slipest_dbc_status_loss_t loss;
    if (node == NULL || out == NULL) return SLIPEST_E_NULL;
    if (cap < 3u) return SLIPEST_E_OVERFLOW;
    m.model_hash = slipest_model_hash32(node->mq); /* 0 before init */
    m.lib_version = SLIPEST_LIB_VERSION;
    m.windows_done = (uint16_t)node->c.windows_done;
    rx.frames_received = node->c.frames_received;
    rx.frames_rejected = node->c.frames_rejected;
    loss.samples_dropped = node->ex.samples_dropped;
    loss.windows_flagged = node->ex.windows_flagged;
    out[0].id = SLIPEST_DBC_STATUS_MODEL_FRAME_ID;
    out[0].dlc = SLIPEST_DBC_STATUS_MODEL_LENGTH;
    slipest_dbc_status_model_pack(out[0].data, &m, sizeof out[0].data);
    out[1].id = SLIPEST_DBC_STATUS_RX_FRAME_ID;
    out[1].dlc = SLIPEST_DBC_STATUS_RX_LENGTH;
    slipest_dbc_status_rx_pack(out[1].data, &rx, sizeof out[1].data);
    out[2].id = SLIPEST_DBC_STATUS_LOSS_FRAME_ID;
    out[2].dlc = SLIPEST_DBC_STATUS_LOSS_LENGTH;
    slipest_dbc_status_loss_pack(out[2].data, &loss, sizeof out[2].data);
    return 3;
}

/* a STATUS_MODEL frame with an all-zero payload: "status due here" for a profile with its own status */
static int status_marker(const slipest_node_t *node, slipest_frame_t *out, size_t cap)
{
    (void)node;
    (void)cap;
    out->id = SLIPEST_DBC_STATUS_MODEL_FRAME_ID;
    out->dlc = SLIPEST_DBC_STATUS_MODEL_LENGTH;
    (void)memset(out->data, 0, sizeof out->data);
    return 1;
}

/* Run both inference paths on integer features and write the three estimate frames.
 * n_samples = 0 for windows fed as FEATURES frames. */
static int emit_estimate(slipest_node_t *node, uint16_t window_counter, const int16_t feat_q[SLIPEST_N_FEATURES],
                         const slipest_window_t *w, uint8_t flags, uint8_t n_samples, uint32_t extra_saturations,
                         slipest_frame_t *out)
{
    struct slipest_dbc_slip_estimate_t est;
    struct slipest_dbc_slip_logits_01_t l01;
    struct slipest_dbc_slip_logits_2_t l2;
    int32_t logits[3] = {0, 0, 0};
    uint32_t sat = extra_saturations;
    uint8_t cls_q = CLASS_NONE, cls_f = CLASS_NONE;
    int n = 0;

    if (!(flags & SLIPEST_FLAG_INVALID)) {
        uint16_t infer_sat = 0;
        int r = slipest_infer_q(node->mq, feat_q, logits, &infer_sat); /* SLIPEST_E_NULL if never initialised */
        if (r >= 0) {
            cls_q = (uint8_t)r;
            sat += infer_sat;
        } else {
            flags |= SLIPEST_FLAG_INVALID;
            logits[0] = logits[1] = logits[2] = 0;
        }
#ifndef SLIPEST_Q_ONLY
        {
            float feat_f[SLIPEST_N_FEATURES];
            float logits_f[3];
            int i, rf;
            if (w != NULL) {
                rf = slipest_window_features_f32(w, feat_f);
            } else {
                /* fed features are integers in raw LSB units: back to physical units */
                static const float lsb[SLIPEST_N_FEATURES] = {0.001f, 0.001f, 0.01f, 0.01f, 0.001f, 0.001f,
                                                               0.001f, 0.001f, 0.001f, 0.001f, 0.0001f, 0.0001f};
                for (i = 0; i < SLIPEST_N_FEATURES; i++) {
                    feat_f[i] = (float)feat_q[i] * lsb[i];
                }
                rf = SLIPEST_OK;
            }
            if (rf >= 0) {
                if (node->mf != NULL) {
                    rf = slipest_infer_f32(node->mf, feat_f, logits_f);
                } else {
                    rf = SLIPEST_E_STATE; /* no float model: no float class */
                }
            }
            if (rf >= 0) {
                cls_f = (uint8_t)rf;
            }
        }
#else
        (void)w;
#endif
    }
    if (sat > 0) flags |= SLIPEST_FLAG_SATURATION;
    node->c.saturations += sat;

    est.window_counter = window_counter;
    est.slip_class = cls_q;
    est.slip_class_f32 = cls_f;
    est.flags = flags;
    est.n_samples = n_samples;
    est.saturations = (uint16_t)(sat > 0xFFFFu ? 0xFFFFu : sat);
    l01.logit_0 = logits[0];
    l01.logit_1 = logits[1];
    l2.logit_2 = logits[2];
    l2.window_counter = window_counter;

    out[n].id = SLIPEST_DBC_SLIP_ESTIMATE_FRAME_ID;
    out[n].dlc = SLIPEST_DBC_SLIP_ESTIMATE_LENGTH;
    slipest_dbc_slip_estimate_pack(out[n].data, &est, sizeof out[n].data);
    n++;
    out[n].id = SLIPEST_DBC_SLIP_LOGITS_01_FRAME_ID;
    out[n].dlc = SLIPEST_DBC_SLIP_LOGITS_01_LENGTH;
    slipest_dbc_slip_logits_01_pack(out[n].data, &l01, sizeof out[n].data);
    n++;
    out[n].id = SLIPEST_DBC_SLIP_LOGITS_2_FRAME_ID;
    out[n].dlc = SLIPEST_DBC_SLIP_LOGITS_2_LENGTH;
    slipest_dbc_slip_logits_2_pack(out[n].data, &l2, sizeof out[n].data);
    n++;
    node->c.windows_done++;
    if (node->c.windows_done % SLIPEST_STATUS_EVERY == 0u) {
        sync_counters(node);
        n += node->status(node, out + n, 3u);
    }
    return n;
}

static int emit_window(slipest_node_t *node, const slipest_window_t *w, slipest_frame_t *out)
{
    int16_t feat_q[SLIPEST_N_FEATURES];
    int sat = 0;
    uint8_t flags = w->flags;
    if (!(flags & SLIPEST_FLAG_INVALID)) {
        sat = slipest_window_features_q(w, feat_q);
        if (sat < 0) return sat;
    } else {
        memset(feat_q, 0, sizeof feat_q);
    }
    return emit_estimate(node, (uint16_t)(w->index & 0xFFFFu), feat_q, w, flags, w->n, (uint32_t)sat, out);
}

static int push_sample(slipest_node_t *node, slipest_frame_t *out)
{
    slipest_window_t closed[SLIPEST_MAX_CLOSED];
    int k, n = 0;
    int r = slipest_extractor_push(&node->ex, node->asm_counter, node->asm_sample, closed);
    /* the assembler only moves forward, but after >32767 slots of incomplete samples the
     * extractor may still see this sample as behind: reject the completing frame */
    if (r < 0) return reject(node, r);
    for (k = 0; k < r; k++) {
        int e = emit_window(node, &closed[k], out + n);
        if (e < 0) return e;
        n += e;
    }
    return n;
}

/* Telemetry frame of type `type` (0 wheel, 1 imu, 2 attitude) for sample `counter`. */
static int handle_telem(slipest_node_t *node, unsigned type, uint16_t counter, const int16_t *vals, unsigned first,
                        unsigned count, slipest_frame_t *out)
{
    unsigned i;
    if (node->asm_valid) {
        uint16_t delta = (uint16_t)(counter - node->asm_counter);
        if (delta >= 32768u) return reject(node, SLIPEST_E_ORDER); /* late */
        if (delta == 0) {
            if (node->asm_mask & (1u << type)) return reject(node, SLIPEST_E_ORDER); /* duplicate */
        } else {
            /* a later sample starts; an incomplete one is dropped (its slot counts as missing) */
            node->asm_counter = counter;
            node->asm_mask = 0;
        }
    } else {
        node->asm_valid = 1;
        node->asm_counter = counter;
        node->asm_mask = 0;
    }
    for (i = 0; i < count; i++) {
        node->asm_sample[first + i] = vals[i];
    }
    node->asm_mask |= (uint8_t)(1u << type);
    if (node->asm_mask == TELEM_ALL) return push_sample(node, out);
    return 0;
}

static int handle_features(slipest_node_t *node, unsigned part, uint16_t wc, const int16_t v[3], slipest_frame_t *out)
{
    int n;
    if (node->feat_mask != 0 && wc != node->feat_counter) {
        /* the incomplete set is discarded, one rejection per discarded frame */
        uint8_t m = node->feat_mask;
        while (m) {
            node->c.frames_rejected += m & 1u;
            m >>= 1;
        }
        node->feat_mask = 0;
    }
    if (node->feat_mask & (1u << part)) return reject(node, SLIPEST_E_ORDER); /* duplicate part */
    node->feat_counter = wc;
    node->feat_q[3u * part] = v[0];
    node->feat_q[3u * part + 1u] = v[1];
    node->feat_q[3u * part + 2u] = v[2];
    node->feat_mask |= (uint8_t)(1u << part);
    if (node->feat_mask != FEATURES_ALL) return 0;
    node->feat_mask = 0;
    n = emit_estimate(node, wc, node->feat_q, NULL, SLIPEST_FLAG_FEATURES_INPUT, 0, 0, out);
    return n;
}

int slipest_node_telemetry(slipest_node_t *node, unsigned type, uint16_t counter, const int16_t *values,
                           slipest_frame_t *out, size_t cap)
{
    /* where each frame's signals go in the sample (the order of handle_telem's callers below) */
    static const uint8_t first[3] = {0u, 2u, 5u};
    static const uint8_t count[3] = {2u, 3u, 2u};
    if (node == NULL || values == NULL || out == NULL) return SLIPEST_E_NULL;
    if (cap < SLIPEST_NODE_MAX_OUT) return SLIPEST_E_OVERFLOW;
    node->c.frames_received++;
    if (type > 2u) return reject(node, SLIPEST_E_UNKNOWN_ID);
    node->status = status_marker;
    return handle_telem(node, type, counter, values, first[type], count[type], out);
}

static void reset_state(slipest_node_t *node)
{
    slipest_extractor_reset_grid(&node->ex);
    node->asm_valid = 0;
    node->asm_mask = 0;
    node->feat_mask = 0;
}

/* DLC that the DBC requires for an input frame ID, or -1 if the ID is not an input */
static int expected_dlc(uint32_t id)
{
    switch (id) {
    case SLIPEST_DBC_TELEM_WHEEL_FRAME_ID: return SLIPEST_DBC_TELEM_WHEEL_LENGTH;
    case SLIPEST_DBC_TELEM_IMU_FRAME_ID: return SLIPEST_DBC_TELEM_IMU_LENGTH;
    case SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID: return SLIPEST_DBC_TELEM_ATTITUDE_LENGTH;
    case SLIPEST_DBC_FEATURES_0_FRAME_ID: return SLIPEST_DBC_FEATURES_0_LENGTH;
    case SLIPEST_DBC_FEATURES_1_FRAME_ID: return SLIPEST_DBC_FEATURES_1_LENGTH;
    case SLIPEST_DBC_FEATURES_2_FRAME_ID: return SLIPEST_DBC_FEATURES_2_LENGTH;
    case SLIPEST_DBC_FEATURES_3_FRAME_ID: return SLIPEST_DBC_FEATURES_3_LENGTH;
    case SLIPEST_DBC_CONTROL_FRAME_ID: return SLIPEST_DBC_CONTROL_LENGTH;
    default: return -1;
    }
}

int slipest_node_handle(slipest_node_t *node, const slipest_frame_t *in, slipest_frame_t *out, size_t cap)
{
    int want;
    if (node == NULL || in == NULL || out == NULL) return SLIPEST_E_NULL;
    if (cap < SLIPEST_NODE_MAX_OUT) return SLIPEST_E_OVERFLOW;
    node->c.frames_received++;
    node->status = slipest_node_status;
    want = expected_dlc(in->id);
    if (want < 0) return reject(node, SLIPEST_E_UNKNOWN_ID);
    if (in->dlc != (uint8_t)want) return reject(node, SLIPEST_E_LENGTH);

    switch (in->id) {
    case SLIPEST_DBC_TELEM_WHEEL_FRAME_ID: {
        struct slipest_dbc_telem_wheel_t m;
        int16_t v[2];
        slipest_dbc_telem_wheel_unpack(&m, in->data, in->dlc);
        v[0] = m.wheel_speed;
        v[1] = m.motor_current;
        return handle_telem(node, 0, m.sample_counter, v, 0, 2, out);
    }
    case SLIPEST_DBC_TELEM_IMU_FRAME_ID: {
        struct slipest_dbc_telem_imu_t m;
        int16_t v[3];
        slipest_dbc_telem_imu_unpack(&m, in->data, in->dlc);
        v[0] = m.acc_x;
        v[1] = m.acc_y;
        v[2] = m.acc_z;
        return handle_telem(node, 1, m.sample_counter, v, 2, 3, out);
    }
    case SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID: {
        struct slipest_dbc_telem_attitude_t m;
        int16_t v[2];
        slipest_dbc_telem_attitude_unpack(&m, in->data, in->dlc);
        v[0] = m.roll;
        v[1] = m.pitch;
        return handle_telem(node, 2, m.sample_counter, v, 5, 2, out);
    }
    case SLIPEST_DBC_FEATURES_0_FRAME_ID: {
        struct slipest_dbc_features_0_t m;
        int16_t v[3];
        slipest_dbc_features_0_unpack(&m, in->data, in->dlc);
        v[0] = m.w_vel_mean;
        v[1] = m.w_vel_std;
        v[2] = m.curr_mean;
        return handle_features(node, 0, m.window_counter, v, out);
    }
    case SLIPEST_DBC_FEATURES_1_FRAME_ID: {
        struct slipest_dbc_features_1_t m;
        int16_t v[3];
        slipest_dbc_features_1_unpack(&m, in->data, in->dlc);
        v[0] = m.curr_std;
        v[1] = m.acc_x_mean;
        v[2] = m.acc_x_std;
        return handle_features(node, 1, m.window_counter, v, out);
    }
    case SLIPEST_DBC_FEATURES_2_FRAME_ID: {
        struct slipest_dbc_features_2_t m;
        int16_t v[3];
        slipest_dbc_features_2_unpack(&m, in->data, in->dlc);
        v[0] = m.acc_y_mean;
        v[1] = m.acc_y_std;
        v[2] = m.acc_z_mean;
        return handle_features(node, 2, m.window_counter, v, out);
    }
    case SLIPEST_DBC_FEATURES_3_FRAME_ID: {
        struct slipest_dbc_features_3_t m;
        int16_t v[3];
        slipest_dbc_features_3_unpack(&m, in->data, in->dlc);
        v[0] = m.acc_z_std;
        v[1] = m.pitch_mean;
        v[2] = m.roll_mean;
        return handle_features(node, 3, m.window_counter, v, out);
    }
    default: { /* CONTROL */
        struct slipest_dbc_control_t m;
        slipest_dbc_control_unpack(&m, in->data, in->dlc);
        if (m.command == SLIPEST_CMD_RESET) {
            reset_state(node);
            return 0;
        }
        if (m.command == SLIPEST_CMD_STATUS) return slipest_node_status(node, out, cap);
        return reject(node, SLIPEST_E_FORMAT);
    }
    }
}
