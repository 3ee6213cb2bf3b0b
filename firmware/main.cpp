// caphub: the firmware of the inertial motion-capture hub.
#include "firmware/cli/app.h"

int main(int argc, char** argv) {
    return caphub::firmware::runCli(argc, argv);
}
