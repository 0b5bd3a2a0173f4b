/*
 * qrf_parser.c: a parser for qrfield's serial lines (protocol 2), for a gripper controller.
 *
 *   $QRF,<seq>,<t_ms>,<age_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,
 *        <sx>,<sy>,<sz>,<salpha>,<sbeta>,<sgamma>,<status>*<CRC>\r\n             a pose line
 *   $QRM,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,
 *        <sx>,<sy>,<sz>,<salpha>,<sbeta>,<sgamma>,<n_used>,<status>*<CRC>\r\n   the answer to MEAS,n
 *   $QRA,<command>,<field>[,<field>...]*<CRC>\r\n                             other answers
 *
 * (docs/serial.md and docs/conventions.md of qrfield.) x, y, z and their sigmas: mm with 1
 * decimal; alpha, beta, gamma and theirs: degrees with 2 decimals. $QRF status: OK (act on it),
 * AMBIG (flip unresolved: do not act), SIM (not a live camera: never act) with the pose filled;
 * NOQR, NOCONV, STALE, NOSRC with it empty. A pose's age when the line's last byte arrived is
 * age_ms + bytes * 10 / baud. CRC: CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no
 * final XOR) over the bytes between '$' and '*', 4 uppercase hex digits. A line is at most 160
 * bytes with its CR LF.
 *
 * Strict: numbers as qrfield writes them (no '+', no spaces, no leading zeros, no "-0.0", exactly
 * 1 or 2 decimals), ranges checked (|x| <= 999999.9 mm, alpha and gamma in (-180, 180], beta in
 * [-90, 90], sigmas >= 0), fields of the wrong count or content rejected. Read `out` only after
 * qrf_feed() returned QRF_FRAME, QRF_MEAS or QRF_ANSWER: a rejected line may have written part of it.
 *
 * Commands to qrfield (qrf_command() writes them with their CRC): PING, HELLO, STREAM,ON|OFF,
 * RATE,<hz>, MEAS,<n> (n 1..100).
 *
 * No floating point, no heap, fixed buffers: positions come out in tenths of a mm and angles in
 * hundredths of a degree as int32 (x = 12.5 mm -> pos_dmm[0] = 125); an unknown sigma is -1. Feed
 * it one byte at a time from the UART interrupt or main loop with qrf_feed(); it resynchronises on
 * every '$'. Plain C99, MIT licence.
 *
 * Build the demo: gcc -std=c99 -O2 -Wall -Wextra -Werror -pedantic -o qrf_parser qrf_parser.c
 * It reads bytes on stdin and prints one line per complete line ("FRAME ...", "MEAS ...",
 * "ANSWER ...", "OTHER", or "ERR crc|format|length"). "qrf_parser --command MEAS 10" prints a command.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define QRF_MAX_LINE 160          /* longest line, CR LF included */
#define QRF_MAX_BODY (QRF_MAX_LINE - 2)
#define QRF_MAX_FIELDS 17
#define QRF_MAX_ANSWER_FIELDS 8
#define QRF_MAX_FIELD 40          /* an answer field's bytes at most */
#define QRF_UNKNOWN (-1)          /* a sigma qrfield did not know */

typedef struct {
    uint16_t seq;
    uint32_t t_ms;          /* capture (or, STALE / NOSRC, line) time, ms since the stream started */
    uint8_t has_age;        /* 0 only for STALE / NOSRC before any frame was captured */
    uint32_t age_ms;        /* capture to the line handed to the port, ms */
    uint8_t has_pose;       /* 1 for OK, AMBIG, SIM */
    int32_t pos_dmm[3];     /* x, y, z: camera frame, tenths of a millimetre */
    int32_t ang_cdeg[3];    /* alpha, beta, gamma: hundredths of a degree */
    int32_t std_pos_dmm[3]; /* standard uncertainty (1 sigma), same units; QRF_UNKNOWN if not known */
    int32_t std_ang_cdeg[3];
    char status[8];         /* OK, AMBIG, SIM, NOQR, NOCONV, STALE, NOSRC */
} qrf_frame;

typedef struct {
    uint16_t seq;           /* counts the measurements */
    uint32_t t_ms;          /* capture time of the last frame averaged */
    uint8_t has_pose;       /* 1 for OK, AMBIG, SIM */
    int32_t pos_dmm[3];     /* mean x, y, z */
    int32_t ang_cdeg[3];    /* mean alpha, beta, gamma (circular means) */
    int32_t std_pos_dmm[3]; /* standard uncertainty of the mean; QRF_UNKNOWN if not known */
    int32_t std_ang_cdeg[3];
    uint8_t n_used;         /* frames averaged, 1..100 */
    char status[8];         /* OK, AMBIG, SIM, NOQR, NOCONV, NOSRC, TIMEOUT */
} qrf_measurement;

typedef struct {
    char command[17];       /* the command answered, e.g. "PING"; "?" for a line qrfield could not read */
    uint8_t ok;             /* 0 when field[0] is "ERR" (field[1] is then the reason) */
    uint8_t n_fields;       /* 1..QRF_MAX_ANSWER_FIELDS */
    char field[QRF_MAX_ANSWER_FIELDS][QRF_MAX_FIELD + 1]; /* "OK", "ERR", HELLO's "QRF2", values */
} qrf_answer;

enum {
    QRF_NONE = 0,          /* no complete line yet */
    QRF_FRAME = 1,         /* out->frame holds a $QRF line */
    QRF_MEAS = 2,          /* out->meas holds a $QRM answer */
    QRF_ANSWER = 3,        /* out->answer holds a $QRA answer */
    QRF_ERR_CRC = -1,      /* no valid *CRC, or the CRC does not match */
    QRF_ERR_FORMAT = -2,   /* CRC right, content wrong: field count, number grammar, range, status */
    QRF_ERR_LENGTH = -3,   /* longer than QRF_MAX_LINE: dropped */
    QRF_OTHER = -4         /* a valid line of another talker (a $QRC command echoed back) */
};

typedef struct {
    qrf_frame frame;
    qrf_measurement meas;
    qrf_answer answer;
} qrf_message;

typedef struct {
    char buf[QRF_MAX_BODY];
    uint8_t len;
    uint8_t active;   /* inside a line (a '$' was seen) */
    uint8_t overflow; /* the current line was too long */
} qrf_reader;

/* CRC-16/CCITT-FALSE; qrf_crc16("123456789", 9) == 0x29B1. */
uint16_t qrf_crc16(const char *data, size_t n) {
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc ^= (uint16_t)((uint16_t)(uint8_t)data[i] << 8);
        for (int b = 0; b < 8; b++)
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    }
    return crc;
}

static int hex_upper(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

static int is_digit(char c) { return c >= '0' && c <= '9'; }

/* "0" or [1-9][0-9]* of at most 10 digits, <= max. */
static int parse_uint(const char *s, size_t n, uint32_t max, uint32_t *out) {
    uint32_t v = 0;
    if (n == 0 || n > 10 || (n > 1 && s[0] == '0')) return -1;
    for (size_t i = 0; i < n; i++) {
        uint32_t d;
        if (!is_digit(s[i])) return -1;
        d = (uint32_t)(s[i] - '0');
        if (v > (max - d) / 10u) return -1;
        v = v * 10u + d;
    }
    *out = v;
    return 0;
}

/* -?(0|[1-9][0-9]{0,int_digits-1})\.[0-9]{decimals}, not "-0.0": the value times 10^decimals. */
static int parse_fixed(const char *s, size_t n, int decimals, int int_digits, int allow_negative, int32_t *out) {
    size_t i = 0, start;
    int32_t v = 0;
    int neg = 0;
    if (n > 0 && s[0] == '-') {
        if (!allow_negative) return -1;
        neg = 1;
        i = 1;
    }
    start = i;
    while (i < n && is_digit(s[i])) i++;
    if (i == start || (int)(i - start) > int_digits || (s[start] == '0' && i - start > 1)) return -1;
    if (i >= n || s[i] != '.') return -1;
    if (n - i - 1 != (size_t)decimals) return -1;
    for (size_t k = start; k < n; k++) {
        if (k == i) continue;
        if (!is_digit(s[k])) return -1;
        v = v * 10 + (s[k] - '0');
    }
    if (neg && v == 0) return -1;
    *out = neg ? -v : v;
    return 0;
}

static int field_is(const char *f, size_t n, const char *text) {
    return n == strlen(text) && memcmp(f, text, n) == 0;
}

static int one_of(const char *f, size_t n, const char *const *words) {
    for (int k = 0; words[k]; k++)
        if (field_is(f, n, words[k])) return 1;
    return 0;
}

static void copy_text(char *dst, const char *f, size_t n) { /* the caller checked n fits */
    memcpy(dst, f, n);
    dst[n] = '\0';
}

static const char *const POSE_STATUSES[] = {"OK", "AMBIG", "SIM", NULL};
static const char *const FRAME_EMPTY[] = {"NOQR", "NOCONV", "STALE", "NOSRC", NULL};
static const char *const MEAS_EMPTY[] = {"NOQR", "NOCONV", "NOSRC", "TIMEOUT", NULL};

/* Pose and sigmas from fields f[0..12): x y z alpha beta gamma sx sy sz salpha sbeta sgamma. */
static int parse_pose(const char *const *f, const size_t *n, int32_t pos[3], int32_t ang[3], int32_t spos[3],
                      int32_t sang[3]) {
    for (int k = 0; k < 3; k++) {
        if (parse_fixed(f[k], n[k], 1, 6, 1, &pos[k])) return -1;
        if (parse_fixed(f[3 + k], n[3 + k], 2, 3, 1, &ang[k])) return -1;
        spos[k] = sang[k] = QRF_UNKNOWN;
        if (n[6 + k] && parse_fixed(f[6 + k], n[6 + k], 1, 6, 0, &spos[k])) return -1;
        if (n[9 + k] && parse_fixed(f[9 + k], n[9 + k], 2, 3, 0, &sang[k])) return -1;
    }
    if (ang[0] <= -18000 || ang[0] > 18000 || ang[2] <= -18000 || ang[2] > 18000) return -1;
    if (ang[1] < -9000 || ang[1] > 9000) return -1;
    return 0;
}

static int all_empty(const size_t *n, int count) {
    for (int k = 0; k < count; k++)
        if (n[k] != 0) return 0;
    return 1;
}

static int parse_qrf(const char *const *f, const size_t *n, size_t nf, qrf_frame *out) {
    uint32_t seq, t_ms;
    if (nf != 17 || n[16] >= sizeof out->status) return QRF_ERR_FORMAT;
    if (parse_uint(f[1], n[1], 65535u, &seq) || parse_uint(f[2], n[2], 4294967295u, &t_ms)) return QRF_ERR_FORMAT;
    if (one_of(f[16], n[16], POSE_STATUSES)) {
        if (parse_pose(f + 4, n + 4, out->pos_dmm, out->ang_cdeg, out->std_pos_dmm, out->std_ang_cdeg))
            return QRF_ERR_FORMAT;
        out->has_pose = 1;
    } else if (one_of(f[16], n[16], FRAME_EMPTY)) {
        if (!all_empty(n + 4, 12)) return QRF_ERR_FORMAT;
        out->has_pose = 0;
    } else {
        return QRF_ERR_FORMAT;
    }
    out->has_age = n[3] != 0;
    out->age_ms = 0;
    if (out->has_age ? parse_uint(f[3], n[3], 4294967295u, &out->age_ms)
                     : !(field_is(f[16], n[16], "STALE") || field_is(f[16], n[16], "NOSRC")))
        return QRF_ERR_FORMAT;
    out->seq = (uint16_t)seq;
    out->t_ms = t_ms;
    copy_text(out->status, f[16], n[16]);
    return QRF_FRAME;
}

static int parse_qrm(const char *const *f, const size_t *n, size_t nf, qrf_measurement *out) {
    uint32_t seq, t_ms, n_used = 0;
    if (nf != 17 || n[16] >= sizeof out->status) return QRF_ERR_FORMAT;
    if (parse_uint(f[1], n[1], 65535u, &seq) || parse_uint(f[2], n[2], 4294967295u, &t_ms)) return QRF_ERR_FORMAT;
    if (one_of(f[16], n[16], POSE_STATUSES)) {
        if (parse_pose(f + 3, n + 3, out->pos_dmm, out->ang_cdeg, out->std_pos_dmm, out->std_ang_cdeg))
            return QRF_ERR_FORMAT;
        if (parse_uint(f[15], n[15], 100u, &n_used) || n_used < 1) return QRF_ERR_FORMAT;
        out->has_pose = 1;
    } else if (one_of(f[16], n[16], MEAS_EMPTY)) {
        if (!all_empty(n + 3, 13)) return QRF_ERR_FORMAT;
        out->has_pose = 0;
    } else {
        return QRF_ERR_FORMAT;
    }
    out->seq = (uint16_t)seq;
    out->t_ms = t_ms;
    out->n_used = (uint8_t)n_used;
    copy_text(out->status, f[16], n[16]);
    return QRF_MEAS;
}

static int parse_qra(const char *const *f, const size_t *n, size_t nf, qrf_answer *out) {
    if (nf < 3 || nf > 2 + QRF_MAX_ANSWER_FIELDS) return QRF_ERR_FORMAT;
    if (n[1] < 1 || n[1] >= sizeof out->command) return QRF_ERR_FORMAT;
    if (!field_is(f[1], n[1], "?"))
        for (size_t i = 0; i < n[1]; i++)
            if (!is_digit(f[1][i]) && !(f[1][i] >= 'A' && f[1][i] <= 'Z')) return QRF_ERR_FORMAT;
    for (size_t k = 2; k < nf; k++)
        if (n[k] > QRF_MAX_FIELD) return QRF_ERR_FORMAT;
    if (field_is(f[2], n[2], "ERR") && (nf < 4 || n[3] == 0)) return QRF_ERR_FORMAT;
    copy_text(out->command, f[1], n[1]);
    out->n_fields = (uint8_t)(nf - 2);
    for (size_t k = 2; k < nf; k++) copy_text(out->field[k - 2], f[k], n[k]);
    out->ok = !field_is(f[2], n[2], "ERR");
    return QRF_ANSWER;
}

/* Parse one line from '$' up to (not including) its CR / LF. */
int qrf_parse_line(const char *line, size_t len, qrf_message *out) {
    const char *field[QRF_MAX_FIELDS];
    size_t flen[QRF_MAX_FIELDS];
    size_t nf = 0, star, i;
    int h;
    uint16_t crc = 0;
    if (len > QRF_MAX_BODY) return QRF_ERR_LENGTH;
    if (len < 7 || line[0] != '$' || line[len - 5] != '*') return QRF_ERR_CRC;
    star = len - 5;
    for (i = star + 1; i < len; i++) {
        if ((h = hex_upper(line[i])) < 0) return QRF_ERR_CRC;
        crc = (uint16_t)((crc << 4) | (uint16_t)h);
    }
    if (qrf_crc16(line + 1, star - 1) != crc) return QRF_ERR_CRC;
    for (i = 1; i < star; i++) /* printable ASCII only, no '$' or '*' inside */
        if (line[i] < ' ' || line[i] > '~' || line[i] == '$' || line[i] == '*') return QRF_ERR_FORMAT;
    field[0] = line + 1;
    for (i = 1; i <= star; i++) {
        if (i == star || line[i] == ',') {
            if (nf >= QRF_MAX_FIELDS) return QRF_ERR_FORMAT;
            flen[nf] = (size_t)(line + i - field[nf]);
            nf++;
            if (i < star && nf < QRF_MAX_FIELDS) field[nf] = line + i + 1;
        }
    }
    if (field_is(field[0], flen[0], "QRF")) return parse_qrf(field, flen, nf, &out->frame);
    if (field_is(field[0], flen[0], "QRM")) return parse_qrm(field, flen, nf, &out->meas);
    if (field_is(field[0], flen[0], "QRA")) return parse_qra(field, flen, nf, &out->answer);
    if (flen[0] < 1 || flen[0] > 8) return QRF_ERR_FORMAT;
    for (i = 0; i < flen[0]; i++)
        if (!is_digit(field[0][i]) && !(field[0][i] >= 'A' && field[0][i] <= 'Z')) return QRF_ERR_FORMAT;
    return QRF_OTHER;
}

/* Feed one received byte. Returns QRF_NONE until a line ends (CR or LF), then what qrf_parse_line says. */
int qrf_feed(qrf_reader *r, char c, qrf_message *out) {
    if (c == '$') { /* a new line starts here, whatever came before */
        r->active = 1;
        r->overflow = 0;
        r->len = 0;
    }
    if (!r->active) return QRF_NONE; /* garbage, or the LF after a CR */
    if (c == '\r' || c == '\n') {
        r->active = 0;
        return r->overflow ? QRF_ERR_LENGTH : qrf_parse_line(r->buf, r->len, out);
    }
    if (r->len >= QRF_MAX_BODY) {
        r->overflow = 1;
        return QRF_NONE;
    }
    r->buf[r->len++] = c;
    return QRF_NONE;
}

/* Write "$QRC,<command>[,<arg>]*CRC\r\n" into buf (size bytes, NUL-terminated); returns its length,
 * or -1 if it does not fit. arg may be NULL (PING). E.g. qrf_command(buf, sizeof buf, "MEAS", "10"). */
int qrf_command(char *buf, size_t size, const char *command, const char *arg) {
    static const char hex[] = "0123456789ABCDEF";
    size_t n = 0;
    uint16_t crc;
    const char *parts[3] = {"QRC", command, arg};
    if (size < 1) return -1;
    buf[n++] = '$';
    for (int k = 0; k < 3 && parts[k]; k++) {
        if (k > 0) {
            if (n + 1 >= size) return -1;
            buf[n++] = ',';
        }
        for (const char *p = parts[k]; *p; p++) {
            if (n + 1 >= size) return -1;
            buf[n++] = *p;
        }
    }
    if (n + 8 > size) return -1;
    crc = qrf_crc16(buf + 1, n - 1);
    buf[n++] = '*';
    for (int shift = 12; shift >= 0; shift -= 4) buf[n++] = hex[(crc >> shift) & 15u];
    buf[n++] = '\r';
    buf[n++] = '\n';
    buf[n] = '\0';
    return (int)n;
}

#ifndef QRF_NO_MAIN
static void print_values(const int32_t *v, int count, int sigmas) {
    for (int k = 0; k < count; k++) {
        if (sigmas && v[k] == QRF_UNKNOWN)
            printf(" ?");
        else
            printf(" %ld", (long)v[k]);
    }
}

int main(int argc, char **argv) {
    static qrf_reader reader;
    static qrf_message msg;
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
            printf("FRAME %u %lu", msg.frame.seq, (unsigned long)msg.frame.t_ms);
            if (msg.frame.has_age)
                printf(" %lu", (unsigned long)msg.frame.age_ms);
            else
                printf(" -");
            printf(" %s", msg.frame.status);
            if (msg.frame.has_pose) {
                print_values(msg.frame.pos_dmm, 3, 0);
                print_values(msg.frame.ang_cdeg, 3, 0);
                print_values(msg.frame.std_pos_dmm, 3, 1);
                print_values(msg.frame.std_ang_cdeg, 3, 1);
            }
            printf("\n");
        } else if (result == QRF_MEAS) {
            printf("MEAS %u %lu %s", msg.meas.seq, (unsigned long)msg.meas.t_ms, msg.meas.status);
            if (msg.meas.has_pose) {
                print_values(msg.meas.pos_dmm, 3, 0);
                print_values(msg.meas.ang_cdeg, 3, 0);
                print_values(msg.meas.std_pos_dmm, 3, 1);
                print_values(msg.meas.std_ang_cdeg, 3, 1);
                printf(" %u", msg.meas.n_used);
            }
            printf("\n");
        } else if (result == QRF_ANSWER) {
            printf("ANSWER %s", msg.answer.command);
            for (int k = 0; k < msg.answer.n_fields; k++) printf("%c%s", k ? ',' : ' ', msg.answer.field[k]);
            printf("\n");
        } else if (result == QRF_ERR_CRC) {
            printf("ERR crc\n");
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
