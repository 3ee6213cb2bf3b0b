// The guided sensor calibration (sensor_calibration_session.h): start one procedure, cancel it,
// and its status (also in the state document as "sensor_calibration_session").
#include "firmware/serve/sensor_calibration_session.h"
#include "firmware/serve/web_state.h"

namespace caphub::firmware::serve {

void WebServer::State::sensorCalibrationRoutes() {
    SensorCalibrationSession* session = options.calibrationSession;
    const auto offered = [session](httplib::Response& res) {
        if (session == nullptr) {
            fail(res, 404, "this hub offers no guided sensor calibration");
        }
        return session != nullptr;
    };
    server.Get("/api/sensor-calibration",
               guarded([session, offered](const httplib::Request&, httplib::Response& res) {
                   if (offered(res)) {
                       reply(res, 200, session->status());
                   }
               }));
    server.Post("/api/sensor-calibration",
                command([session, offered](const Json& b, httplib::Response& res) {
                    if (!offered(res)) {
                        return;
                    }
                    auto request = parseSensorCalibrationRequest(b);
                    if (!request) {
                        failWith(res, request.error());
                        return;
                    }
                    if (auto r = session->start(*request); !r) {
                        fail(res, r.error().code == EBUSY ? 409 : statusFor(r.error()),
                             r.error().message);
                        return;
                    }
                    reply(res, 202, session->status());
                }));
    server.Post("/api/sensor-calibration/cancel",
                command([session, offered](const Json&, httplib::Response& res) {
                    if (offered(res)) {
                        session->cancel();
                        reply(res, 200, Json{{"ok", true}});
                    }
                }));
}

}  // namespace caphub::firmware::serve
