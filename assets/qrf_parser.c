/*
 * qrf_parser.c: a small parser for qrfield's serial pose frames, for a gripper controller.
 *
 *   $QRF,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<status>*<CS>\r\n
 *
 * x, y, z: mm with 1 decimal; alpha, beta, gamma: degrees with 2 decimals; status OK, NOQR,
 * NOCONV or STALE (pose fields empty unless OK; STALE repeats the previous frame's fields).
 * CS: XOR of every byte between '$' and '*', two hex digits.
 *
 * No floating point and no heap: positions come out in tenths of a mm and angles in hundredths
 * of a degree as int32 (x = 12.5 mm -> x_dmm = 125). Feed it one byte at a time from the UART
 * interrupt or main loop with qrf_feed(); it resynchronises on every '$'. Plain C99, MIT licence.
 *
 * Build the demo: gcc -std=c99 -Wall -Wextra -o qrf_parser qrf_parser.c
 * It reads bytes on stdin and prints one line per complete line: the frame, or ERR and the reason.
 */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define QRF_MAX_LINE 96 /* longest frame is 86 bytes with CR LF */

typedef struct {
    uint16_t seq;
    uint32_t t_ms;
    uint8_t has_pose;     /* 1 when the six pose fields are filled */
    int32_t pos_dmm[3];   /* x, y, z: camera frame, tenths of a millimetre */
    int32_t ang_cdeg[3];  /* alpha, beta, gamma: hundredths of a degree */
    char status[8];       /* "OK", "NOQR", "NOCONV" or "STALE" */
} qrf_frame;

enum {
    QRF_NONE = 0,        /* no complete line yet */
    QRF_FRAME = 1,       /* *out holds a frame */
    QRF_ERR_CHECKSUM = -1,
    QRF_ERR_FORMAT = -2, /* wrong field count, number, status or no '*CS' */
    QRF_ERR_LENGTH = -3, /* line too long: dropped */
    QRF_OTHER = -4       /* a valid line that is not $QRF (a command from another talker) */
};

typedef struct {
    char buf[QRF_MAX_LINE];
    uint8_t len;
    uint8_t active;   /* inside a line (a '$' was seen) */
    uint8_t overflow; /* the current line was too long */
} qrf_reader;

static int hex_value(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
}

/* Parse an unsigned decimal integer from s[0..n); returns 0 on success. */
static int parse_uint(const char *s, size_t n, uint32_t max, uint32_t *out) {
    uint32_t v = 0;
    if (n == 0 || n > 10) return -1;
    for (size_t i = 0; i < n; i++) {
        if (s[i] < '0' || s[i] > '9') return -1;
        uint32_t d = (uint32_t)(s[i] - '0');
        if (v > (max - d) / 10) return -1;
        v = v * 10 + d;
    }
    *out = v;
    return 0;
}

/* Parse "-123.4" with exactly `decimals` digits after the point into an integer scaled by 10^decimals. */
static int parse_fixed(const char *s, size_t n, int decimals, int32_t *out) {
    int32_t v = 0;
    int neg = 0, seen_point = 0, after = 0, digits = 0;
    size_t i = 0;
    if (n > 0 && s[0] == '-') { neg = 1; i = 1; }
    for (; i < n; i++) {
        if (s[i] == '.' && !seen_point) { seen_point = 1; continue; }
        if (s[i] < '0' || s[i] > '9') return -1;
        if (++digits > 9) return -1;
        if (seen_point) after++;
        v = v * 10 + (s[i] - '0');
    }
    if (digits == 0 || !seen_point || after != decimals) return -1;
    *out = neg ? -v : v;
    return 0;
}

/* Parse one line from '$' up to (not including) CR/LF. */
int qrf_parse_line(const char *line, size_t len, qrf_frame *out) {
    const char *star;
    uint8_t cs = 0;
    const char *field[10];
    size_t flen[10];
    size_t nf = 0;
    if (len < 4 || line[0] != '$') return QRF_ERR_FORMAT;
    star = memchr(line, '*', len);
    if (!star || (size_t)(line + len - star) != 3) return QRF_ERR_FORMAT;
    if (hex_value(star[1]) < 0 || hex_value(star[2]) < 0) return QRF_ERR_FORMAT;
    for (const char *p = line + 1; p < star; p++) cs ^= (uint8_t)*p;
    if (cs != (uint8_t)(hex_value(star[1]) * 16 + hex_value(star[2]))) return QRF_ERR_CHECKSUM;
    /* Split the body at commas. */
    field[0] = line + 1;
    for (const char *p = line + 1; p <= star; p++) {
        if (p == star || *p == ',') {
            if (nf >= 10) return QRF_ERR_FORMAT;
            flen[nf] = (size_t)(p - field[nf]);
            nf++;
            if (p < star && nf < 10) field[nf] = p + 1;
        }
    }
    if (!(flen[0] == 3 && memcmp(field[0], "QRF", 3) == 0)) return QRF_OTHER;
    if (nf != 10) return QRF_ERR_FORMAT;
    uint32_t seq, t_ms;
    if (parse_uint(field[1], flen[1], 65535u, &seq) || parse_uint(field[2], flen[2], 4294967295u, &t_ms))
        return QRF_ERR_FORMAT;
    out->seq = (uint16_t)seq;
    out->t_ms = t_ms;
    if (flen[9] == 0 || flen[9] >= sizeof out->status) return QRF_ERR_FORMAT;
    memcpy(out->status, field[9], flen[9]);
    out->status[flen[9]] = '\0';
    int ok = strcmp(out->status, "OK") == 0, stale = strcmp(out->status, "STALE") == 0;
    if (!ok && !stale && strcmp(out->status, "NOQR") != 0 && strcmp(out->status, "NOCONV") != 0)
        return QRF_ERR_FORMAT;
    size_t empty = 0;
    for (int k = 3; k < 9; k++) empty += flen[k] == 0;
    if (empty == 6 && !ok) {
        out->has_pose = 0;
        memset(out->pos_dmm, 0, sizeof out->pos_dmm);
        memset(out->ang_cdeg, 0, sizeof out->ang_cdeg);
        return QRF_FRAME;
    }
    if (!ok && !stale) return QRF_ERR_FORMAT; /* NOQR / NOCONV must have empty fields */
    for (int k = 0; k < 3; k++) {
        if (parse_fixed(field[3 + k], flen[3 + k], 1, &out->pos_dmm[k])) return QRF_ERR_FORMAT;
        if (parse_fixed(field[6 + k], flen[6 + k], 2, &out->ang_cdeg[k])) return QRF_ERR_FORMAT;
    }
    out->has_pose = 1;
    return QRF_FRAME;
}

/* Feed one received byte. Returns QRF_NONE until a line ends, then what qrf_parse_line says. */
int qrf_feed(qrf_reader *r, char c, qrf_frame *out) {
    if (c == '$') { /* a new line starts here, whatever came before */
        r->active = 1;
        r->overflow = 0;
        r->len = 0;
    }
    if (!r->active) return QRF_NONE; /* garbage between lines */
    if (c == '\r' || c == '\n') {
        int result = r->overflow ? QRF_ERR_LENGTH : qrf_parse_line(r->buf, r->len, out);
        r->active = 0;
        return result;
    }
    if (r->len >= QRF_MAX_LINE) {
        r->overflow = 1;
        return QRF_NONE;
    }
    r->buf[r->len++] = c;
    return QRF_NONE;
}

#ifndef QRF_NO_MAIN
static void print_fixed(int32_t v, int decimals) {
    int32_t scale = decimals == 1 ? 10 : 100;
    int32_t a = v < 0 ? -v : v;
    printf(" %s%ld.%0*ld", v < 0 ? "-" : "", (long)(a / scale), decimals, (long)(a % scale));
}

int main(void) {
    qrf_reader reader = {0};
    qrf_frame frame;
    int c;
    while ((c = getchar()) != EOF) {
        int result = qrf_feed(&reader, (char)c, &frame);
        if (result == QRF_FRAME) {
            printf("FRAME %u %lu %s", frame.seq, (unsigned long)frame.t_ms, frame.status);
            if (frame.has_pose) {
                for (int k = 0; k < 3; k++) print_fixed(frame.pos_dmm[k], 1);
                for (int k = 0; k < 3; k++) print_fixed(frame.ang_cdeg[k], 2);
            }
            printf("\n");
        } else if (result == QRF_ERR_CHECKSUM) {
            printf("ERR checksum\n");
        } else if (result == QRF_ERR_FORMAT) {
            printf("ERR format\n");
        } else if (result == QRF_ERR_LENGTH) {
            printf("ERR length\n");
        } else if (result == QRF_OTHER) {
            printf("OTHER\n");
        }
    }
    return 0;
}
#endif
