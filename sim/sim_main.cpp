// The simulators' shared options, log lines and signals (sim_main.h).
#include "sim_main.h"

#include <cstdarg>
#include <cstdlib>
#include <ctime>

volatile std::sig_atomic_t g_sim_stop = 0;

namespace {

void on_signal(int) { g_sim_stop = 1; }

}  // namespace

void sim_signals() {
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);
}

double sim_cpu_seconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }  // the process's CPU time

void sim_log(bool quiet, const char *fmt, ...) {
    if (quiet) return;
    va_list ap;
    va_start(ap, fmt);
    fputs("wmsim: ", stdout);
    vfprintf(stdout, fmt, ap);
    fputc('\n', stdout);
    fflush(stdout);
    va_end(ap);
}

void sim_usage(const char *argv0, const SimBoardInfo &info) {
    if (info.soc)
        fprintf(stderr,
                "usage: %s --firmware FILE.hex [--port N (default %d, 0 = any)] [--fast] [--exit-on-close]\n"
                "          [--no-socket] [--max-cycles N] [--trace FILE.fst] [--profile FILE [--pc-trace FILE]]\n"
                "          [--progress S] [--quiet]\n",
                argv0, info.default_port);
    else
        fprintf(stderr, "usage: %s [--port N (default %d, 0 = any)] [--exit-on-close] [--max-cycles N] [--quiet]\n",
                argv0, info.default_port);
}

bool sim_parse(int argc, char **argv, const SimBoardInfo &info, SimOptions *o) {
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        auto value = [&](const char *name) -> const char * {
            if (i + 1 >= argc) {
                fprintf(stderr, "wmsim: error: %s needs a value\n", name);
                return nullptr;
            }
            return argv[++i];
        };
        bool soc_only = a == "--firmware" || a == "--trace" || a == "--profile" || a == "--pc-trace" ||
                        a == "--progress" ||
                        a == "--fast" || a == "--no-socket";
        if (soc_only && !info.soc) {
            fprintf(stderr, "wmsim: error: unknown option '%s'\n", a.c_str());
            return false;
        }
        if (a == "--firmware" || a == "--trace" || a == "--profile" || a == "--pc-trace") {
            const char *v = value(a.c_str());
            if (!v) return false;
            (a == "--firmware" ? o->firmware : a == "--trace" ? o->trace : a == "--profile" ? o->profile : o->pc_trace) = v;
        } else if (a == "--port") {
            const char *v = value("--port");
            if (!v) return false;
            char *end = nullptr;
            long p = strtol(v, &end, 10);
            if (*end || p < 0 || p > 65535) {
                fprintf(stderr, "wmsim: error: bad port '%s'\n", v);
                return false;
            }
            o->port = static_cast<int>(p);
        } else if (a == "--max-cycles") {
            const char *v = value("--max-cycles");
            if (!v) return false;
            char *end = nullptr;
            o->max_cycles = strtoull(v, &end, 10);
            if (*end) {
                fprintf(stderr, "wmsim: error: bad --max-cycles '%s'\n", v);
                return false;
            }
        } else if (a == "--progress") {
            const char *v = value("--progress");
            if (!v) return false;
            char *end = nullptr;
            o->progress = strtod(v, &end);
            if (*end || !(o->progress > 0)) {
                fprintf(stderr, "wmsim: error: bad --progress '%s' (seconds > 0)\n", v);
                return false;
            }
        } else if (a == "--fast") {
            o->fast = true;
        } else if (a == "--exit-on-close") {
            o->exit_on_close = true;
        } else if (a == "--no-socket") {
            o->no_socket = true;
        } else if (a == "--quiet") {
            o->quiet = true;
        } else if (a == "-h" || a == "--help") {
            sim_usage(argv[0], info);
            exit(0);
        } else if (a.rfind("+", 0) == 0) {
            // a Verilator plusarg: passed through
        } else {
            fprintf(stderr, "wmsim: error: unknown option '%s'\n", a.c_str());
            return false;
        }
    }
    if (!info.soc) return true;
#if !VM_TRACE
    if (!o->trace.empty()) {
        fprintf(stderr, "wmsim: error: this simulator was built without tracing: make sim TRACE=1\n");
        return false;
    }
#endif
    if (!o->pc_trace.empty() && o->profile.empty()) {
        fprintf(stderr, "wmsim: error: --pc-trace needs --profile (it traces the profile's PCs)\n");
        return false;
    }
    if (o->firmware.empty()) {
        fprintf(stderr, "wmsim: error: --firmware FILE.hex is required\n");
        return false;
    }
    if (FILE *f = fopen(o->firmware.c_str(), "r")) {
        fclose(f);
    } else {
        fprintf(stderr, "wmsim: error: cannot read firmware '%s'\n", o->firmware.c_str());
        return false;
    }
    return true;
}
