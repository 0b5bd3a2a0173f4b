/*
 * qrf_parser.c: a small parser for qrfield's serial lines, for a gripper controller.
 *
 *   $QRF,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<status>*<CS>\r\n      a pose frame
 *   $QRM,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,
 *        <sx>,<sy>,<sz>,<salpha>,<sbeta>,<sgamma>,<n_used>,<status>*<CS>\r\n     the answer to MEAS,n
 *   $QRA,<command>,OK*<CS>\r\n  or  $QRA,<command>,ERR,<reason>*<CS>\r\n         other answers
 *
 * (docs/conventions.md of qrfield.) x, y, z and sx, sy, sz: mm with 1 decimal; alpha, beta, gamma
 * and their s*: degrees with 2 decimals. $QRF status: OK (a live camera's pose) or SIM (the virtual
 * bench or a recording: never act on it as a measurement) with the pose fields filled; NOQR, NOCONV
 * or NOSRC (no camera frames) with them empty; STALE repeats the previous frame's fields. $QRM
 * status: OK or SIM with every field filled, else NOQR, NOCONV, NOSRC or TIMEOUT with the number
 * fields empty. CS: XOR of every byte between '$' and '*', two hex digits. A line is at most 160
 * bytes with its CR LF.
 *
 * Commands to qrfield (qrf_command() writes them): PING, STREAM,ON, STREAM,OFF, MEAS,<n> (n 1..100).
 *
 * No floating point and no heap: positions come out in tenths of a mm and angles in hundredths
 * of a degree as int32 (x = 12.5 mm -> x_dmm = 125). Feed it one byte at a time from the UART
 * interrupt or main loop with qrf_feed(); it resynchronises on every '$'. Plain C99, MIT licence.
 *
 * Build the demo: gcc -std=c99 -Wall -Wextra -o qrf_parser qrf_parser.c
 * It reads bytes on stdin and prints one line per complete line: the frame, measurement or answer,
 * or ERR and the reason. "qrf_parser --command MEAS 10" prints the command line instead.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define QRF_MAX_LINE 160 /* longest valid line, CR LF included */
#define QRF_MAX_FIELDS 17

typedef struct {
    uint16_t seq;
    uint32_t t_ms;
    uint8_t has_pose;     /* 1 when the six pose fields are filled */
    int32_t pos_dmm[3];   /* x, y, z: camera frame, tenths of a millimetre */
    int32_t ang_cdeg[3];  /* alpha, beta, gamma: hundredths of a degree */
    char status[8];       /* "OK", "SIM", "NOQR", "NOCONV", "NOSRC" or "STALE" */
} qrf_frame;

typedef struct {
    uint16_t seq;          /* counts the measurements */
    uint32_t t_ms;         /* capture time of the last frame averaged */
    uint8_t has_pose;      /* 1 for OK and SIM: every field below is filled */
    int32_t pos_dmm[3];    /* mean x, y, z, tenths of a mm */
    int32_t ang_cdeg[3];   /* mean alpha, beta, gamma (circular means), hundredths of a degree */
    int32_t std_pos_dmm[3];  /* standard deviations over the frames, same units */
    int32_t std_ang_cdeg[3];
    uint8_t n_used;        /* frames averaged, 1..100 */
    char status[8];        /* "OK", "SIM", "NOQR", "NOCONV", "NOSRC" or "TIMEOUT" */
} qrf_measurement;

typedef struct {
    char command[17];      /* the command answered, e.g. "PING" */
    uint8_t ok;            /* 1 for OK, 0 for ERR */
    char reason[41];       /* why, for ERR (no commas, at most 40 bytes) */
} qrf_answer;

enum {
    QRF_NONE = 0,        /* no complete line yet */
    QRF_FRAME = 1,       /* out->frame holds a $QRF frame */
    QRF_MEAS = 2,        /* out->meas holds a $QRM measurement */
    QRF_ANSWER = 3,      /* out->answer holds a $QRA answer */
    QRF_ERR_CHECKSUM = -1,
    QRF_ERR_FORMAT = -2, /* wrong field count, number, status or no '*CS' */
    QRF_ERR_LENGTH = -3, /* line too long: dropped */
    QRF_OTHER = -4       /* a valid line of another talker (a command) */
};

typedef struct {
    qrf_frame frame;
    qrf_measurement meas;
    qrf_answer answer;
} qrf_message;

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

static int field_is(const char *f, size_t n, const char *text) {
    return n == strlen(text) && memcmp(f, text, n) == 0;
}

/* Copy field f[0..n) into dst (size bytes, NUL-terminated); -1 if it does not fit. */
static int copy_field(char *dst, size_t size, const char *f, size_t n) {
    if (n >= size) return -1;
    memcpy(dst, f, n);
    dst[n] = '\0';
    return 0;
}

/* Three positions (1 decimal) then three angles (2 decimals) from fields f[0..6). */
static int parse_pose(const char *const *f, const size_t *n, int32_t pos[3], int32_t ang[3]) {
    for (int k = 0; k < 3; k++) {
        if (parse_fixed(f[k], n[k], 1, &pos[k])) return -1;
        if (parse_fixed(f[3 + k], n[3 + k], 2, &ang[k])) return -1;
    }
    return 0;
}

static int all_empty(const size_t *n, int count) {
    for (int k = 0; k < count; k++)
        if (n[k] != 0) return 0;
    return 1;
}

static int parse_qrf(const char *const *f, const size_t *n, size_t nf, qrf_frame *out) {
    uint32_t seq, t_ms;
    if (nf != 10) return QRF_ERR_FORMAT;
    if (parse_uint(f[1], n[1], 65535u, &seq) || parse_uint(f[2], n[2], 4294967295u, &t_ms)) return QRF_ERR_FORMAT;
    out->seq = (uint16_t)seq;
    out->t_ms = t_ms;
    if (copy_field(out->status, sizeof out->status, f[9], n[9])) return QRF_ERR_FORMAT;
    int filled = !strcmp(out->status, "OK") || !strcmp(out->status, "SIM");
    int empty = !strcmp(out->status, "NOQR") || !strcmp(out->status, "NOCONV") || !strcmp(out->status, "NOSRC");
    int stale = !strcmp(out->status, "STALE");
    if (!filled && !empty && !stale) return QRF_ERR_FORMAT;
    if (all_empty(n + 3, 6) && !filled) {
        out->has_pose = 0;
        memset(out->pos_dmm, 0, sizeof out->pos_dmm);
        memset(out->ang_cdeg, 0, sizeof out->ang_cdeg);
        return QRF_FRAME;
    }
    if (empty) return QRF_ERR_FORMAT; /* NOQR / NOCONV / NOSRC must have empty fields */
    if (parse_pose(f + 3, n + 3, out->pos_dmm, out->ang_cdeg)) return QRF_ERR_FORMAT;
    out->has_pose = 1;
    return QRF_FRAME;
}

static int parse_qrm(const char *const *f, const size_t *n, size_t nf, qrf_measurement *out) {
    uint32_t seq, t_ms, n_used;
    if (nf != 17) return QRF_ERR_FORMAT;
    if (parse_uint(f[1], n[1], 65535u, &seq) || parse_uint(f[2], n[2], 4294967295u, &t_ms)) return QRF_ERR_FORMAT;
    out->seq = (uint16_t)seq;
    out->t_ms = t_ms;
    if (copy_field(out->status, sizeof out->status, f[16], n[16])) return QRF_ERR_FORMAT;
    int filled = !strcmp(out->status, "OK") || !strcmp(out->status, "SIM");
    if (!filled) {
        if (strcmp(out->status, "NOQR") && strcmp(out->status, "NOCONV") && strcmp(out->status, "NOSRC") &&
            strcmp(out->status, "TIMEOUT"))
            return QRF_ERR_FORMAT;
        if (!all_empty(n + 3, 13)) return QRF_ERR_FORMAT; /* the number fields are empty */
        memset(out, 0, offsetof(qrf_measurement, status));
        out->seq = (uint16_t)seq;
        out->t_ms = t_ms;
        return QRF_MEAS;
    }
    if (parse_pose(f + 3, n + 3, out->pos_dmm, out->ang_cdeg)) return QRF_ERR_FORMAT;
    if (parse_pose(f + 9, n + 9, out->std_pos_dmm, out->std_ang_cdeg)) return QRF_ERR_FORMAT;
    for (int k = 0; k < 3; k++)
        if (out->std_pos_dmm[k] < 0 || out->std_ang_cdeg[k] < 0) return QRF_ERR_FORMAT;
    if (parse_uint(f[15], n[15], 100u, &n_used) || n_used < 1) return QRF_ERR_FORMAT;
    out->n_used = (uint8_t)n_used;
    out->has_pose = 1;
    return QRF_MEAS;
}

static int parse_qra(const char *const *f, const size_t *n, size_t nf, qrf_answer *out) {
    if (copy_field(out->command, sizeof out->command, f[1], n[1])) return QRF_ERR_FORMAT;
    out->reason[0] = '\0';
    if (nf == 3 && field_is(f[2], n[2], "OK")) {
        out->ok = 1;
        return QRF_ANSWER;
    }
    if (nf == 4 && field_is(f[2], n[2], "ERR") && !copy_field(out->reason, sizeof out->reason, f[3], n[3])) {
        out->ok = 0;
        return QRF_ANSWER;
    }
    return QRF_ERR_FORMAT;
}

/* Parse one line from '$' up to (not including) CR/LF. */
int qrf_parse_line(const char *line, size_t len, qrf_message *out) {
    const char *star;
    uint8_t cs = 0;
    const char *field[QRF_MAX_FIELDS];
    size_t flen[QRF_MAX_FIELDS];
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
            if (nf >= QRF_MAX_FIELDS) return QRF_ERR_FORMAT;
            flen[nf] = (size_t)(p - field[nf]);
            nf++;
            if (p < star && nf < QRF_MAX_FIELDS) field[nf] = p + 1;
        }
    }
    if (field_is(field[0], flen[0], "QRF")) return parse_qrf(field, flen, nf, &out->frame);
    if (field_is(field[0], flen[0], "QRM")) return parse_qrm(field, flen, nf, &out->meas);
    if (field_is(field[0], flen[0], "QRA") && nf >= 3) return parse_qra(field, flen, nf, &out->answer);
    if (field_is(field[0], flen[0], "QRA")) return QRF_ERR_FORMAT;
    return QRF_OTHER;
}

/* Feed one received byte. Returns QRF_NONE until a line ends, then what qrf_parse_line says. */
int qrf_feed(qrf_reader *r, char c, qrf_message *out) {
    if (c == '$') { /* a new line starts here, whatever came before */
        r->active = 1;
        r->overflow = 0;
        r->len = 0;
    }
    if (!r->active) return QRF_NONE; /* garbage between lines */
    if (c == '\r' || c == '\n') {
        /* The line with its CR LF must fit in QRF_MAX_LINE bytes. */
        int result = (r->overflow || r->len + 2 > QRF_MAX_LINE) ? QRF_ERR_LENGTH : qrf_parse_line(r->buf, r->len, out);
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

/* Write the command "$QRC,<command>[,<arg>]*CS\r\n" into buf (size bytes); returns its length,
 * or -1 if it does not fit. arg may be NULL (PING). E.g. qrf_command(buf, sizeof buf, "MEAS", "10"). */
int qrf_command(char *buf, size_t size, const char *command, const char *arg) {
    static const char hex[] = "0123456789ABCDEF";
    size_t n = 0;
    uint8_t cs = 0;
    const char *parts[3] = {"QRC", command, arg};
    if (size < 1) return -1;
    buf[n++] = '$';
    for (int k = 0; k < 3 && parts[k]; k++) {
        if (k > 0) {
            if (n + 1 >= size) return -1;
            buf[n++] = ',';
            cs ^= ',';
        }
        for (const char *p = parts[k]; *p; p++) {
            if (n + 1 >= size) return -1;
            buf[n++] = *p;
            cs ^= (uint8_t)*p;
        }
    }
    if (n + 5 >= size) return -1;
    buf[n++] = '*';
    buf[n++] = hex[cs >> 4];
    buf[n++] = hex[cs & 15];
    buf[n++] = '\r';
    buf[n++] = '\n';
    buf[n] = '\0';
    return (int)n;
}

#ifndef QRF_NO_MAIN
static void print_fixed(int32_t v, int decimals) {
    int32_t scale = decimals == 1 ? 10 : 100;
    int32_t a = v < 0 ? -v : v;
    printf(" %s%ld.%0*ld", v < 0 ? "-" : "", (long)(a / scale), decimals, (long)(a % scale));
}

static void print_pose(const int32_t pos[3], const int32_t ang[3]) {
    for (int k = 0; k < 3; k++) print_fixed(pos[k], 1);
    for (int k = 0; k < 3; k++) print_fixed(ang[k], 2);
}

int main(int argc, char **argv) {
    qrf_reader reader = {0};
    qrf_message msg;
    int c;
    if (argc >= 3 && strcmp(argv[1], "--command") == 0) {
        char line[QRF_MAX_LINE];
        if (qrf_command(line, sizeof line, argv[2], argc > 3 ? argv[3] : NULL) < 0) return 1;
        fputs(line, stdout);
        return 0;
    }
    while ((c = getchar()) != EOF) {
        int result = qrf_feed(&reader, (char)c, &msg);
        if (result == QRF_FRAME) {
            printf("FRAME %u %lu %s", msg.frame.seq, (unsigned long)msg.frame.t_ms, msg.frame.status);
            if (msg.frame.has_pose) print_pose(msg.frame.pos_dmm, msg.frame.ang_cdeg);
            printf("\n");
        } else if (result == QRF_MEAS) {
            printf("MEAS %u %lu %s", msg.meas.seq, (unsigned long)msg.meas.t_ms, msg.meas.status);
            if (msg.meas.has_pose) {
                print_pose(msg.meas.pos_dmm, msg.meas.ang_cdeg);
                print_pose(msg.meas.std_pos_dmm, msg.meas.std_ang_cdeg);
                printf(" %u", msg.meas.n_used);
            }
            printf("\n");
        } else if (result == QRF_ANSWER) {
            printf("ANSWER %s %s%s%s\n", msg.answer.command, msg.answer.ok ? "OK" : "ERR",
                   msg.answer.ok ? "" : " ", msg.answer.reason);
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
