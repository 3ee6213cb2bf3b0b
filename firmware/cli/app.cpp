#include "firmware/cli/app.h"

#include <string>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "firmware/cli/commands.h"
#include "firmware/cli/info.h"
#include "hal/core/log.h"

namespace caphub::firmware {

int runCli(int argc, char** argv) {
    CLI::App app{"caphub: firmware of a standalone inertial motion-capture hub"};
    app.name("caphub");
    app.set_help_all_flag("--help-all", "Print help for every subcommand");
    app.require_subcommand(1);
    app.fallthrough();

    std::string logSpec = "info";
    app.add_option("--log", logSpec,
                   "Log levels: a default and per-module overrides, e.g. 'warn,hal=debug'")
        ->capture_default_str();
    app.set_version_flag("-V,--version", versionLine());

    int exitCode = kExitOk;
    app.parse_complete_callback([&] {
        if (auto r = log::configure(logSpec); !r) {
            throw CLI::ValidationError("--log", r.error().message);
        }
    });

    addBoardsCommand(app, exitCode);
    addInfoCommands(app, exitCode);
    addRunCommand(app, exitCode);
    addFusionCommand(app, exitCode);
    addSimCommand(app, exitCode);
    addCalibrateCommand(app, exitCode);
    addSelftestCommand(app, exitCode);
    addReplayCommand(app, exitCode);
    addStatusCommand(app, exitCode);
    addExportCommand(app, exitCode);
    addEvaluateCommand(app, exitCode);
    addImportCommand(app, exitCode);
    addServeCommand(app, exitCode);
    addReprocessCommand(app, exitCode);

    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        (void)app.exit(e);
        return kExitUsage;
    }
    return exitCode;
}

}  // namespace caphub::firmware
