use super::*;
use serde_json::{json, Value};

/// `aptscope decode --json samples/kdc101-session.pcapng`
const KDC101: &str = r##"{"type":"stream","stream":0,"stream_name":"/dev/ttyUSB0","settings":"115200 8N1 RTS/CTS"}
{"type":"detect","proto":"apt","certain":true,"apt":1.000,"ell":0.000}
{"n":1,"proto":"apt","type":"frame","offset":0,"len":6,"raw":"050000005001","msgid":5,"msgid_hex":"0x0005","name":"HW_REQ_INFO","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"fields":{},"diag":[],"dir":"h2d","ts_ns":1764000000050000000,"stream":0}
{"n":2,"proto":"apt","type":"frame","offset":0,"len":90,"raw":"0600540081503bfd9b014b444331303100002c000b000300000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000010000000100","msgid":6,"msgid_hex":"0x0006","name":"HW_GET_INFO","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":84,"fields":{"serial_number":27000123,"model_number":"KDC101","hw_type":"BRUSHLESS_DC_CONTROLLER","fw_minor":11,"fw_interim":0,"fw_major":3,"internal":"000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000","hw_version":1,"mod_state":0,"nchs":1},"pair":1,"latency_ms":2,"diag":[],"dir":"d2h","ts_ns":1764000000052000000,"stream":0}
{"n":3,"proto":"apt","type":"frame","offset":6,"len":6,"raw":"100201015001","msgid":528,"msgid_hex":"0x0210","name":"MOD_SET_CHANENABLESTATE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1","enable_state":"ENABLE"},"diag":[],"dir":"h2d","ts_ns":1764000000102000000,"stream":0}
{"n":4,"proto":"apt","type":"frame","offset":12,"len":6,"raw":"110201005001","msgid":529,"msgid_hex":"0x0211","name":"MOD_REQ_CHANENABLESTATE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1"},"diag":[],"dir":"h2d","ts_ns":1764000000152000000,"stream":0}
{"n":5,"proto":"apt","type":"frame","offset":90,"len":6,"raw":"120201010150","msgid":530,"msgid_hex":"0x0212","name":"MOD_GET_CHANENABLESTATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1","enable_state":"ENABLE"},"pair":4,"latency_ms":2,"diag":[],"dir":"d2h","ts_ns":1764000000154000000,"stream":0}
{"n":6,"proto":"apt","type":"frame","offset":18,"len":6,"raw":"110000005001","msgid":17,"msgid_hex":"0x0011","name":"HW_START_UPDATEMSGS","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"fields":{},"diag":[],"dir":"h2d","ts_ns":1764000000204000000,"stream":0}
{"n":7,"proto":"apt","type":"frame","offset":24,"len":6,"raw":"430401005001","msgid":1091,"msgid_hex":"0x0443","name":"MOT_MOVE_HOME","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1"},"diag":[],"dir":"h2d","ts_ns":1764000000254000000,"stream":0}
{"n":8,"proto":"apt","type":"frame","offset":96,"len":20,"raw":"91040e0081500100000000007800000020030080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":0,"velocity":120,"status_bits":["MOVING_CCW","MOTOR_CONNECTED","HOMING","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000000354000000,"stream":0}
{"n":9,"proto":"apt","type":"frame","offset":116,"len":20,"raw":"91040e008150010050fbffff7800000020030080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":-1200,"velocity":120,"status_bits":["MOVING_CCW","MOTOR_CONNECTED","HOMING","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000000454000000,"stream":0}
{"n":10,"proto":"apt","type":"frame","offset":136,"len":20,"raw":"91040e0081500100e8eaffff7800000020030080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":-5400,"velocity":120,"status_bits":["MOVING_CCW","MOTOR_CONNECTED","HOMING","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000000554000000,"stream":0}
{"n":11,"proto":"apt","type":"frame","offset":156,"len":20,"raw":"91040e0081500100b8d9ffff7800000020030080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":-9800,"velocity":120,"status_bits":["MOVING_CCW","MOTOR_CONNECTED","HOMING","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000000654000000,"stream":0}
{"n":12,"proto":"apt","type":"frame","offset":176,"len":6,"raw":"440401000150","msgid":1092,"msgid_hex":"0x0444","name":"MOT_MOVE_HOMED","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1"},"pair":7,"latency_ms":2000,"diag":[],"dir":"d2h","ts_ns":1764000002254000000,"stream":0}
{"n":13,"proto":"apt","type":"frame","offset":30,"len":12,"raw":"53040600d0010100009e0200","msgid":1107,"msgid_hex":"0x0453","name":"MOT_MOVE_ABSOLUTE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":true,"data_len":6,"form_note":"long version: position in the data packet","channel":1,"fields":{"chan_ident":"CH1","absolute_position":171520},"diag":[],"dir":"h2d","ts_ns":1764000002304000000,"stream":0}
{"n":14,"proto":"apt","type":"frame","offset":182,"len":20,"raw":"91040e0081500100005000002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":20480,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002404000000,"stream":0}
{"n":15,"proto":"apt","type":"frame","offset":202,"len":20,"raw":"91040e0081500100000c01002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":68608,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002504000000,"stream":0}
{"n":16,"proto":"apt","type":"frame","offset":222,"len":20,"raw":"91040e008150010000dc01002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":121856,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002604000000,"stream":0}
{"n":17,"proto":"apt","type":"frame","offset":242,"len":20,"raw":"91040e0081500100008602002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":165376,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002704000000,"stream":0}
{"n":18,"proto":"apt","type":"frame","offset":262,"len":20,"raw":"91040e0081500100009e02002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":171520,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002804000000,"stream":0}
{"n":19,"proto":"apt","type":"frame","offset":282,"len":20,"raw":"64040e0081500100009e02000000000000250080","msgid":1124,"msgid_hex":"0x0464","name":"MOT_MOVE_COMPLETED","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"form_note":"with status (MOTDCSTATUS structure)","channel":1,"fields":{"chan_ident":"CH1","position":171520,"velocity":0,"status_bits":["MOTOR_CONNECTED","HOMED","SETTLED","ENABLED"]},"pair":13,"latency_ms":502,"diag":[],"dir":"d2h","ts_ns":1764000002806000000,"stream":0}
{"n":20,"proto":"apt","type":"frame","offset":42,"len":6,"raw":"120000005001","msgid":18,"msgid_hex":"0x0012","name":"HW_STOP_UPDATEMSGS","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"fields":{},"diag":[],"dir":"h2d","ts_ns":1764000002856000000,"stream":0}
"##;

/// `aptscope decode --json samples/elliptec-bus.txt`
const ELL_BUS: &str = r##"{"type":"detect","proto":"ell","certain":true,"apt":0.000,"ell":1.000}
{"n":1,"proto":"ell","type":"frame","offset":0,"len":3,"raw":"30696e","text":"0in","addr":"0","dir":"h2d","cmd":"in","name":"REQ_INFORMATION","fields":{},"diag":[],"stream":0}
{"n":2,"proto":"ell","type":"frame","offset":3,"len":35,"raw":"30494e3045313134303032383432303230303131373031363830303032333030300d0a","text":"0IN0E1140028420200117016800023000\r\n","addr":"0","dir":"d2h","cmd":"IN","name":"GET_INFORMATION","fields":{"model":14,"serial":"11400284","year":"2020","firmware":1,"thread_hw":23,"thread":"metric","hw_release":23,"travel":360,"pulses_per_unit":143360},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":1,"diag":[],"stream":0}
{"n":3,"proto":"ell","type":"frame","offset":38,"len":3,"raw":"31696e","text":"1in","addr":"1","dir":"h2d","cmd":"in","name":"REQ_INFORMATION","fields":{},"diag":[],"stream":0}
{"n":4,"proto":"ell","type":"frame","offset":41,"len":35,"raw":"31494e3039313133303031323332303233313530313030313330303030303032300d0a","text":"1IN091130012320231501001300000020\r\n","addr":"1","dir":"d2h","cmd":"IN","name":"GET_INFORMATION","fields":{"model":9,"serial":"11300123","year":"2023","firmware":21,"thread_hw":1,"thread":"metric","hw_release":1,"travel":19,"pulses_per_unit":32},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"pair":3,"diag":[],"stream":0}
{"n":5,"proto":"ell","type":"frame","offset":76,"len":3,"raw":"32696e","text":"2in","addr":"2","dir":"h2d","cmd":"in","name":"REQ_INFORMATION","fields":{},"diag":[],"stream":0}
{"n":6,"proto":"ell","type":"frame","offset":79,"len":35,"raw":"32494e3131313137303034353632303232313730313030314330303030303830300d0a","text":"2IN111170045620221701001C00000800\r\n","addr":"2","dir":"d2h","cmd":"IN","name":"GET_INFORMATION","fields":{"model":17,"serial":"11700456","year":"2022","firmware":23,"thread_hw":1,"thread":"metric","hw_release":1,"travel":28,"pulses_per_unit":2048},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":5,"diag":[],"stream":0}
{"n":7,"proto":"ell","type":"frame","offset":114,"len":3,"raw":"306773","text":"0gs","addr":"0","dir":"h2d","cmd":"gs","name":"REQ_STATUS","fields":{},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":8,"proto":"ell","type":"frame","offset":117,"len":7,"raw":"30475330300d0a","text":"0GS00\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OK"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":7,"diag":[],"stream":0}
{"n":9,"proto":"ell","type":"frame","offset":124,"len":4,"raw":"30686f30","text":"0ho0","addr":"0","dir":"h2d","cmd":"ho","name":"HOME","fields":{"direction":0},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":10,"proto":"ell","type":"frame","offset":128,"len":7,"raw":"30475330390d0a","text":"0GS09\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"BUSY"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":9,"interim":true,"diag":[],"stream":0}
{"n":11,"proto":"ell","type":"frame","offset":135,"len":13,"raw":"30504f30303030303030300d0a","text":"0PO00000000\r\n","addr":"0","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":0},"phys":{"position":{"value":0,"unit":"deg"}},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":9,"diag":[],"stream":0}
{"n":12,"proto":"ell","type":"frame","offset":148,"len":11,"raw":"306d613030303038433030","text":"0ma00008C00","addr":"0","dir":"h2d","cmd":"ma","name":"MOVE_ABSOLUTE","fields":{"position":35840},"phys":{"position":{"value":90,"unit":"deg"}},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":13,"proto":"ell","type":"frame","offset":159,"len":7,"raw":"30475330390d0a","text":"0GS09\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"BUSY"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":12,"interim":true,"diag":[],"stream":0}
{"n":14,"proto":"ell","type":"frame","offset":166,"len":13,"raw":"30504f30303030384330300d0a","text":"0PO00008C00\r\n","addr":"0","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":35840},"phys":{"position":{"value":90,"unit":"deg"}},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":12,"diag":[],"stream":0}
{"n":15,"proto":"ell","type":"frame","offset":179,"len":3,"raw":"316677","text":"1fw","addr":"1","dir":"h2d","cmd":"fw","name":"FORWARD","fields":{},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"diag":[],"stream":0}
{"n":16,"proto":"ell","type":"frame","offset":182,"len":13,"raw":"31504f30303030303032300d0a","text":"1PO00000020\r\n","addr":"1","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":32},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"pair":15,"diag":[],"stream":0}
{"n":17,"proto":"ell","type":"frame","offset":195,"len":11,"raw":"326d613030303032303030","text":"2ma00002000","addr":"2","dir":"h2d","cmd":"ma","name":"MOVE_ABSOLUTE","fields":{"position":8192},"phys":{"position":{"value":4,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":18,"proto":"ell","type":"frame","offset":206,"len":13,"raw":"32504f30303030323030300d0a","text":"2PO00002000\r\n","addr":"2","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":8192},"phys":{"position":{"value":4,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":17,"diag":[],"stream":0}
{"n":19,"proto":"ell","type":"frame","offset":219,"len":11,"raw":"326d723030303031303030","text":"2mr00001000","addr":"2","dir":"h2d","cmd":"mr","name":"MOVE_RELATIVE","fields":{"position":4096},"phys":{"position":{"value":2,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":20,"proto":"ell","type":"frame","offset":230,"len":13,"raw":"32504f30303030333030300d0a","text":"2PO00003000\r\n","addr":"2","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":12288},"phys":{"position":{"value":6,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":19,"diag":[],"stream":0}
{"n":21,"proto":"ell","type":"frame","offset":243,"len":4,"raw":"32636135","text":"2ca5","addr":"2","dir":"h2d","cmd":"ca","name":"CHANGE_ADDRESS","fields":{"new_address":"5"},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":22,"proto":"ell","type":"frame","offset":247,"len":7,"raw":"35475330300d0a","text":"5GS00\r\n","addr":"5","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OK"},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":21,"diag":[],"stream":0}
{"n":23,"proto":"ell","type":"frame","offset":254,"len":3,"raw":"356770","text":"5gp","addr":"5","dir":"h2d","cmd":"gp","name":"GET_POSITION","fields":{},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":24,"proto":"ell","type":"frame","offset":257,"len":13,"raw":"35504f30303030333030300d0a","text":"5PO00003000\r\n","addr":"5","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":12288},"phys":{"position":{"value":6,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":23,"diag":[],"stream":0}
{"n":25,"proto":"ell","type":"frame","offset":270,"len":11,"raw":"356d613030303046303030","text":"5ma0000F000","addr":"5","dir":"h2d","cmd":"ma","name":"MOVE_ABSOLUTE","fields":{"position":61440},"phys":{"position":{"value":30,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":26,"proto":"ell","type":"frame","offset":281,"len":7,"raw":"35475330430d0a","text":"5GS0C\r\n","addr":"5","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OUT_OF_RANGE"},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":25,"diag":[],"stream":0}
{"n":27,"proto":"ell","type":"frame","offset":288,"len":3,"raw":"306776","text":"0gv","addr":"0","dir":"h2d","cmd":"gv","name":"REQ_VELOCITY","fields":{},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":28,"proto":"ell","type":"frame","offset":291,"len":7,"raw":"30475636340d0a","text":"0GV64\r\n","addr":"0","dir":"d2h","cmd":"GV","name":"GET_VELOCITY","fields":{"velocity":100},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":27,"diag":[],"stream":0}
{"n":29,"proto":"ell","type":"frame","offset":298,"len":5,"raw":"3073763332","text":"0sv32","addr":"0","dir":"h2d","cmd":"sv","name":"SET_VELOCITY","fields":{"velocity":50},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":30,"proto":"ell","type":"frame","offset":303,"len":7,"raw":"30475330300d0a","text":"0GS00\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OK"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":29,"diag":[],"stream":0}
{"n":31,"proto":"ell","type":"frame","offset":310,"len":7,"raw":"30425330390d0a","text":"0BS09\r\n","addr":"0","dir":"d2h","cmd":"BS","name":"BUTTON_STATUS","fields":{"status":"BUSY"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":32,"proto":"ell","type":"frame","offset":317,"len":13,"raw":"30424f30303030343630300d0a","text":"0BO00004600\r\n","addr":"0","dir":"d2h","cmd":"BO","name":"BUTTON_POSITION","fields":{"position":17920},"phys":{"position":{"value":45,"unit":"deg"}},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":33,"proto":"ell","type":"frame","offset":330,"len":4,"raw":"31676130","text":"1ga0","addr":"1","dir":"h2d","cmd":"ga","name":"GROUP_ADDRESS","fields":{"new_address":"0"},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"diag":[],"stream":0}
{"n":34,"proto":"ell","type":"frame","offset":334,"len":7,"raw":"30475330300d0a","text":"0GS00\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OK"},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"pair":33,"diag":[],"stream":0}
{"n":35,"proto":"ell","type":"frame","offset":341,"len":3,"raw":"31676a","text":"1gj","addr":"1","dir":"h2d","cmd":"gj","name":"REQ_JOG_STEP_SIZE","fields":{},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"diag":[],"stream":0}
{"proto":"ell","type":"diag","ref":35,"diag":[{"kind":"no_reply","offset":341,"msg":"no reply to record 35"}]}
"##;

/// `aptscope decode --json samples/damaged.bin`
const DAMAGED: &str = r##"{"type":"detect","proto":"apt","certain":false,"apt":0.369,"ell":0.000}
{"n":1,"proto":"apt","type":"garbage","offset":0,"len":4,"raw":"ff0055aa","diag":[{"kind":"garbage","offset":0,"msg":"4 byte(s) that start no frame"}],"dir":"unknown","stream":0}
{"n":2,"proto":"apt","type":"frame","offset":4,"len":6,"raw":"050000005001","msgid":5,"msgid_hex":"0x0005","name":"HW_REQ_INFO","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"fields":{},"diag":[],"dir":"h2d","stream":0}
{"n":3,"proto":"apt","type":"garbage","offset":10,"len":3,"raw":"133700","diag":[{"kind":"garbage","offset":10,"msg":"3 byte(s) that start no frame"}],"dir":"unknown","stream":0}
{"n":4,"proto":"apt","type":"frame","offset":13,"len":8,"raw":"eeee0200d0011234","msgid":61166,"msgid_hex":"0xEEEE","name":null,"src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":true,"data_len":2,"fields":{},"diag":[{"kind":"unknown_id","offset":13,"msg":"unknown message id 0xEEEE"}],"dir":"unknown","stream":0}
{"n":5,"proto":"apt","type":"frame","offset":21,"len":6,"raw":"230201005001","msgid":547,"msgid_hex":"0x0223","name":"MOD_IDENTIFY","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1"},"diag":[],"dir":"h2d","stream":0}
{"n":6,"proto":"apt","type":"frame","offset":27,"len":10,"raw":"53040400a2010100400d","msgid":1107,"msgid_hex":"0x0453","name":"MOT_MOVE_ABSOLUTE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":34,"name":"bay1","bay":1},"data_flag":true,"data_len":4,"fields":{},"diag":[{"kind":"length_mismatch","offset":29,"msg":"data length 4 matches no form of this message"}],"dir":"h2d","stream":0}
{"n":7,"proto":"apt","type":"garbage","offset":37,"len":6,"raw":"5304ffffa201","diag":[{"kind":"absurd_length","offset":37,"msg":"header of 0x0453 claims a 65535-byte data packet (max 255); header skipped"}],"dir":"unknown","stream":0}
{"n":8,"proto":"apt","type":"frame","offset":43,"len":12,"raw":"53040600a2010100400d0300","msgid":1107,"msgid_hex":"0x0453","name":"MOT_MOVE_ABSOLUTE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":34,"name":"bay1","bay":1},"data_flag":true,"data_len":6,"form_note":"long version: position in the data packet","channel":1,"fields":{"chan_ident":"CH1","absolute_position":200000},"diag":[],"dir":"h2d","stream":0}
{"n":9,"proto":"apt","type":"frame","offset":55,"len":10,"raw":"91040e00815001000050","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1"},"diag":[{"kind":"truncated","offset":65,"msg":"truncated: header announces 20 bytes, stream ends after 10"}],"dir":"d2h","stream":0}
{"proto":"apt","type":"diag","ref":2,"diag":[{"kind":"no_reply","offset":4,"msg":"no reply to record 2"}]}
{"proto":"apt","type":"diag","ref":6,"diag":[{"kind":"no_reply","offset":27,"msg":"no reply to record 6"}]}
{"proto":"apt","type":"diag","ref":8,"diag":[{"kind":"no_reply","offset":43,"msg":"no reply to record 8"}]}
"##;

fn records(ndjson: &str) -> Vec<Value> {
    ndjson
        .lines()
        .map(|l| serde_json::from_str(l).expect("golden line is JSON"))
        .collect()
}

fn f(src: &str) -> Filter {
    Filter::parse(src).unwrap_or_else(|e| panic!("{src}: {e}\n{}", e.caret(src)))
}

fn count(recs: &[Value], src: &str) -> usize {
    let flt = f(src);
    recs.iter().filter(|r| flt.matches(r)).count()
}

/// Record numbers (`n`) of the matching records.
fn ns(recs: &[Value], src: &str) -> Vec<u64> {
    let flt = f(src);
    recs.iter()
        .filter(|r| flt.matches(r))
        .filter_map(|r| r.get("n").and_then(Value::as_u64))
        .collect()
}

fn err(src: &str) -> FilterError {
    match Filter::parse(src) {
        Ok(x) => panic!("{src}: parsed as {x:?}"),
        Err(e) => e,
    }
}

fn status_rec() -> Value {
    json!({"n":14,"proto":"apt","type":"frame","offset":182,"len":20,
            "raw":"91040e0081500100005000002c01000010050080","msgid":1169,"msgid_hex":"0x0491",
            "name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h",
            "src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},
            "data_flag":true,"data_len":14,"channel":1,
            "fields":{"chan_ident":"CH1","position":20480,"velocity":300,
                "status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},
            "diag":[],"dir":"d2h","ts_ns":1764000002404000000_u64,"stream":0})
}

fn rack_rec() -> Value {
    json!({"n":8,"proto":"apt","type":"frame","offset":43,"len":12,
            "raw":"53040600a2010100400d0300","msgid":1107,"msgid_hex":"0x0453",
            "name":"MOT_MOVE_ABSOLUTE","msg_dir":"h2d",
            "src":{"addr":1,"name":"host"},"dst":{"addr":35,"name":"bay2","bay":2},
            "data_flag":true,"data_len":6,"channel":1,
            "fields":{"chan_ident":"CH1","absolute_position":200000},"diag":[],"dir":"h2d"})
}

fn ell_reply() -> Value {
    json!({"n":14,"proto":"ell","type":"frame","offset":166,"len":13,
            "raw":"30504f30303030384330300d0a","text":"0PO00008C00\r\n","addr":"0","dir":"d2h",
            "cmd":"PO","name":"POSITION","fields":{"position":35840},
            "phys":{"position":{"value":90,"unit":"deg"}},
            "module":{"first_addr":0,"model":"ELL14","serial":"11400284"},
            "pair":12,"latency_ms":12.5,"ts_ns":2_500_000_000_u64,"diag":[]})
}

fn sub_rec() -> Value {
    json!({"n":3,"proto":"apt","type":"frame","offset":0,"len":10,"msgid":2048,
            "name":"LA_SET_PARAMS","msg_dir":"h2d","src":{"addr":1,"name":"host"},
            "dst":{"addr":80,"name":"usb"},"data_flag":true,"data_len":4,
            "sub":{"id":1,"name":"SETPOINT"},"fields":{"setpoint":1638},
            "phys":{"setpoint":{"value":5.0,"unit":"%"}},"diag":[],"dir":"h2d"})
}

fn yes(rec: &Value, src: &str) -> bool {
    f(src).matches(rec)
}

/// A term on a field narrows a scan to the messages that have it; anything that can
/// match without the field (negation, `||` with a record-level term) does not.
#[test]
fn apt_ids_follow_the_fields_a_filter_needs() {
    let t = Table::global();
    let id = |n: &str| t.msg_by_name(n).map(|m| m.id).expect(n);
    let ids = |f: &str| Filter::parse(f).expect(f).apt_ids(t);
    let pos = ids("apt.position > 1000 && dir == d2h").expect("narrowed");
    assert!(pos.contains(id("MOT_GET_DCSTATUSUPDATE")) && pos.contains(id("MOT_MOVE_COMPLETED")));
    assert!(!pos.contains(id("MOT_MOVE_HOME")) && !pos.contains(0x7FFF));
    let chan = ids("apt.chan == 1").expect("narrowed");
    assert!(chan.contains(id("MOT_MOVE_HOME")) && !chan.contains(id("HW_REQ_INFO")));
    let sub = ids("apt.codes.status_bits").expect("narrowed");
    assert!(sub.contains(id("MOT_GET_DCSTATUSUPDATE")));
    let ell = ids("ell.position > 0").expect("no APT frame");
    assert!(!ell.contains(id("MOT_GET_DCSTATUSUPDATE")));
    for any in [
        "!apt.position",
        "apt.position > 1 || n > 5",
        "apt.fields",
        "dir == h2d",
        "",
    ] {
        assert!(ids(any).is_none(), "{any}");
    }
}

#[test]
fn kdc101_counts() {
    let recs = records(KDC101);
    assert_eq!(recs.len(), 22);
    assert_eq!(count(&recs, r#"apt.name == "MOT_GET_DCSTATUSUPDATE""#), 9);
    assert_eq!(count(&recs, "dir == device"), 13);
    assert_eq!(count(&recs, "dir == host"), 7);
    assert_eq!(count(&recs, "dir == d2h || dir == h2d"), 20);
    assert_eq!(ns(&recs, "apt.fields.position > 100000"), [16, 17, 18, 19]);
    assert_eq!(ns(&recs, "apt.fields.position < 0"), [9, 10, 11]);
    assert_eq!(count(&recs, "apt.fields.position"), 10);
    assert_eq!(count(&recs, "apt.position >= 0"), 7);
    assert_eq!(
        ns(&recs, "apt.fields.status_bits contains HOMED"),
        [14, 15, 16, 17, 18, 19]
    );
    assert_eq!(
        count(&recs, r#"apt.fields.status_bits contains "HOMING""#),
        4
    );
    assert_eq!(ns(&recs, r#"apt.name ~ "^MOT_MOVE""#), [7, 12, 13, 19]);
    assert_eq!(ns(&recs, "apt.name in {HW_REQ_INFO HW_GET_INFO}"), [1, 2]);
    assert_eq!(count(&recs, "apt.fields.velocity >= 300"), 5);
    assert_eq!(count(&recs, "apt.msgid == 0x0491"), 9);
    assert_eq!(count(&recs, "apt.msgid == 1169"), 9);
    assert_eq!(count(&recs, "apt.chan == 1"), 16);
    assert_eq!(count(&recs, "apt.fields.chan_ident == ch1"), 16);
    assert_eq!(count(&recs, "apt.src == usb"), 13);
    assert_eq!(count(&recs, "apt.dst == 0x50"), 7);
    assert_eq!(count(&recs, "apt.data_flag"), 12);
    assert_eq!(count(&recs, "apt.data_flag == false"), 8);
    assert_eq!(count(&recs, "apt.len == 20"), 10);
    assert_eq!(count(&recs, "apt.data_len == 14"), 10);
    assert_eq!(count(&recs, "apt.fields.model_number == kdc101"), 1);
    assert_eq!(count(&recs, r#"apt.form_note contains "long""#), 1);
    assert_eq!(count(&recs, "apt.msg_dir == host"), 7);
    // The detect record is `"proto":"apt"` too; the stream record has no protocol.
    assert_eq!(count(&recs, "apt"), 21);
    assert_eq!(count(&recs, "type == frame"), 20);
    assert_eq!(count(&recs, "stream == 0"), 21);
    assert_eq!(count(&recs, "offset == 0"), 2);
    assert_eq!(count(&recs, "n <= 5"), 5);
    assert_eq!(ns(&recs, "ts > 1764000002.5"), [15, 16, 17, 18, 19, 20]);
    assert_eq!(count(&recs, "ts_ns < 1764000000100000000"), 2);
    assert_eq!(count(&recs, "diag || unpaired || ell"), 0);
    // Request/reply pairs: HW_GET_INFO ↩ 1, MOD_GET_CHANENABLESTATE ↩ 4,
    // MOT_MOVE_HOMED ↩ 7 (2 s later), MOT_MOVE_COMPLETED ↩ 13 (502 ms).
    assert_eq!(ns(&recs, "paired"), [2, 5, 12, 19]);
    assert_eq!(ns(&recs, "apt.pair == 13"), [19]);
    assert_eq!(ns(&recs, "latency > 1s"), [12]);
    assert_eq!(ns(&recs, "latency >= 0.5s && latency < 2000"), [19]);
    assert_eq!(ns(&recs, "latency < 10ms"), [2, 5]);
    assert_eq!(ns(&recs, "apt.latency == 2s"), [12]);
    assert_eq!(
        ns(&recs, "dir == host && !(apt.name ~ MOT) && apt.chan"),
        [3, 4]
    );
}

#[test]
fn elliptec_counts() {
    let recs = records(ELL_BUS);
    assert_eq!(
        count(&recs, "ell"),
        37,
        "the frames and the detection record"
    );
    assert_eq!(count(&recs, "ell.addr == 0"), 17);
    assert_eq!(ns(&recs, "ell.addr == 5"), [22, 23, 24, 25, 26]);
    assert_eq!(count(&recs, "ell.module == ELL14"), 15);
    assert_eq!(ns(&recs, "ell.module == ell9"), [4, 15, 16, 33, 34, 35]);
    assert_eq!(ns(&recs, "ell.phys.position > 45"), [12, 14]);
    assert_eq!(count(&recs, "ell.phys.position >= 45"), 3);
    assert_eq!(ns(&recs, "ell.fields.status == BUSY"), [10, 13, 31]);
    assert_eq!(count(&recs, "ell.cmd == GS"), 7);
    assert_eq!(ns(&recs, "ell.cmd == gs"), [7]);
    assert_eq!(count(&recs, "ell.cmd in {PO BO}"), 7);
    assert_eq!(count(&recs, "ell.name == POSITION"), 6);
    assert_eq!(ns(&recs, "ell.fields.serial == 11400284"), [2]);
    assert_eq!(ns(&recs, "ell.fields.year >= 2022"), [4, 6]);
    assert_eq!(count(&recs, "ell.fields.thread == metric"), 3);
    assert_eq!(count(&recs, "ell.interim"), 2);
    assert_eq!(count(&recs, "paired"), 17);
    assert_eq!(count(&recs, "unpaired"), 1);
    assert_eq!(count(&recs, "diag"), 1);
    assert_eq!(count(&recs, "ell.diag"), 1);
    assert_eq!(count(&recs, "apt.diag"), 0);
    assert_eq!(count(&recs, r#"diag.kind == "no_reply""#), 1);
    assert_eq!(count(&recs, "ref == 35"), 1);
    assert_eq!(count(&recs, "apt.name == POSITION"), 0);
    assert_eq!(count(&recs, "ell.fields.new_address == 5"), 1);
    assert_eq!(count(&recs, r#"ell.text ~ "^0PO""#), 2);
    assert_eq!(ns(&recs, r#"ell.cmd ~ "^g""#), [7, 23, 27, 33, 35]);
    assert_eq!(count(&recs, r#"ell.cmd matches "^G""#), 8);
    assert_eq!(
        ns(&recs, "dir == tx && ell.module.model == ELL17"),
        [17, 19, 21, 23, 25]
    );
}

#[test]
fn damaged_counts() {
    let recs = records(DAMAGED);
    assert_eq!(ns(&recs, "diag"), [1, 3, 4, 6, 7, 9]);
    assert_eq!(ns(&recs, r#"diag.kind == "truncated""#), [9]);
    assert_eq!(ns(&recs, "diag.kind == truncated"), [9]);
    assert_eq!(ns(&recs, "diag contains truncated"), [9]);
    assert_eq!(ns(&recs, "diag.offset == 65"), [9]);
    assert_eq!(ns(&recs, "diag.msg contains \"65535\""), [7]);
    assert_eq!(ns(&recs, "diag.kind in {garbage absurd_length}"), [1, 3, 7]);
    assert_eq!(count(&recs, "type == garbage"), 3);
    assert_eq!(ns(&recs, "apt.msgid && !apt.name"), [4]);
    assert_eq!(ns(&recs, "apt.dst == bay1"), [6, 8]);
    assert_eq!(
        ns(&recs, "apt.dst.bay == 1 && apt.fields.absolute_position"),
        [8]
    );
    assert_eq!(count(&recs, "dir == unknown"), 4);
    assert_eq!(count(&recs, "!diag && type == frame"), 3);
    // Requests never answered: one `diag` record each, about its request.
    assert_eq!(count(&recs, "unpaired"), 3);
    assert_eq!(count(&recs, "type == diag && ref in {2 6 8}"), 3);
    assert_eq!(count(&recs, "diag"), 9);
    assert_eq!(
        count(&recs, "diag.kind == no_reply && diag.offset >= 27"),
        2
    );
}

#[test]
fn comparison_operators() {
    let r = status_rec();
    for (src, want) in [
        ("apt.fields.position == 20480", true),
        ("apt.fields.position eq 20480", true),
        ("apt.fields.position != 20480", false),
        ("apt.fields.position ne 1", true),
        ("apt.fields.position < 20481", true),
        ("apt.fields.position lt 20480", false),
        ("apt.fields.position <= 20480", true),
        ("apt.fields.position le 20479", false),
        ("apt.fields.position > 20479", true),
        ("apt.fields.position gt 20480", false),
        ("apt.fields.position >= 20480", true),
        ("apt.fields.position ge 20481", false),
        ("apt.fields.position > -5", true),
        ("apt.fields.position == 20480.0", true),
        ("apt.fields.position < 20480.5", true),
        ("apt.fields.position == 0x5000", true),
        ("apt.msgid == 0X491", true),
        ("apt.msgid_hex == 0x0491", true),
        ("apt.msgid_hex == \"0X0491\"", true),
        // Strings: equality ignores case; ordering is lexical.
        ("apt.name == mot_get_dcstatusupdate", true),
        ("apt.name != MOT_GET_DCSTATUSUPDATE", false),
        ("apt.name != MOT_MOVE_HOME", true),
        ("apt.name > MOT_A", true),
        ("apt.name < \"MOT_H\"", true),
        ("apt.name >= MOT_GET_DCSTATUSUPDATE", true),
        ("apt.name <= MOT_GET", false),
        // Incompatible types are false, never an error.
        // A number against text compares as written: "MOT_…" is not 5.
        ("apt.name == 5", false),
        ("apt.name != 5", true),
        ("apt.name > 5", false),
        ("apt.fields.position == HOMED", false),
        ("apt.fields.position != HOMED", false),
        ("apt.fields.position < 1s", false),
        ("apt.data_flag == true", true),
        ("apt.data_flag != true", false),
        ("apt.data_flag == \"TRUE\"", true),
        ("apt.data_flag == 1", false),
        // Missing fields: every comparison is false.
        ("apt.fields.max_vel == 1", false),
        ("apt.fields.max_vel != 1", false),
        ("!(apt.fields.max_vel == 1)", true),
    ] {
        assert_eq!(yes(&r, src), want, "{src}");
    }
}

#[test]
fn contains_matches_in() {
    let r = status_rec();
    for (src, want) in [
        ("apt.fields.status_bits contains HOMED", true),
        ("apt.fields.status_bits contains \"homed\"", true),
        // Lists: membership, not substring.
        ("apt.fields.status_bits contains HOME", false),
        ("apt.fields.status_bits == ENABLED", true),
        ("apt.fields.status_bits != ENABLED", false),
        ("apt.fields.status_bits != SETTLED", true),
        ("apt.fields.status_bits in {SETTLED HOMED}", true),
        ("apt.name contains DCSTATUS", true),
        ("apt.name contains dcstatus", true),
        ("apt.name contains MOVE", false),
        ("apt.raw contains \"9104\"", true),
        ("apt.dst contains hos", true),
        ("apt.fields.position contains 2", false),
        ("apt.name ~ \"^MOT_GET\"", true),
        ("apt.name matches \"STATUS.*UPDATE$\"", true),
        ("apt.name ~ \"^mot\"", true),
        ("apt.name ~ \"(?-i)^mot\"", false),
        ("apt.name ~ \"(?-i)^MOT\"", true),
        ("apt.name ~ DCSTATUS", true),
        ("apt.fields.status_bits ~ \"^MOVING_\"", true),
        ("apt.fields.position ~ \"^204\"", true),
        ("apt.dst ~ \"^ho\"", true),
        ("apt.raw ~ \"\\d{4}\"", true),
        ("apt.name in {MOT_MOVE_HOME, MOT_GET_DCSTATUSUPDATE}", true),
        ("apt.name in {\"MOT_MOVE_HOME\"}", false),
        ("apt.name in {}", false),
        ("apt.fields.position in {1 2 20480}", true),
        ("apt.fields.position in {0x5000}", true),
        ("apt.msgid in {5 6}", false),
        ("n in {13,14,15}", true),
    ] {
        assert_eq!(yes(&r, src), want, "{src}");
    }
}

#[test]
fn logic_and_precedence() {
    let r = status_rec();
    for (src, want) in [
        ("apt && ell", false),
        ("apt and not ell", true),
        ("apt || ell", true),
        ("ell or apt", true),
        ("!apt", false),
        ("not not apt", true),
        ("!!apt", true),
        // && binds tighter than ||: true || (false && false)
        ("apt || ell && ell", true),
        // (true || false) && false
        ("(apt || ell) && ell", false),
        // ! binds tighter than &&: (!ell) && apt
        ("!ell && apt", true),
        // !(ell && apt)
        ("!(ell && apt)", true),
        // ! binds tighter than ||: (!apt) || ell
        ("!apt || ell", false),
        ("ell || ell || ell || apt", true),
        ("apt && apt && apt && ell", false),
        ("((apt))", true),
        (
            "(apt.name == X || apt.fields.position > 0) and dir == rx",
            true,
        ),
        ("apt.sub||apt.fields.position", true),
        ("apt.fields.position&&!apt.sub", true),
    ] {
        assert_eq!(yes(&r, src), want, "{src}");
    }
}

#[test]
fn addresses_and_directions() {
    let r = rack_rec();
    for (src, want) in [
        ("apt.dst == bay2", true),
        ("apt.dst == BAY2", true),
        ("apt.dst == bay3", false),
        ("apt.dst == 0x23", true),
        ("apt.dst == 35", true),
        ("apt.dst == 34", false),
        ("apt.dst > 0x21", true),
        ("apt.src == host", true),
        ("apt.src == 1", true),
        ("apt.dst in {bay1 bay2}", true),
        ("apt.dst.bay == 2", true),
        ("dir == host", true),
        ("dir == h2d", true),
        ("dir == tx", true),
        ("dir == device", false),
        ("dir == rx", false),
        ("dir != d2h", true),
        ("dir in {host}", true),
        ("apt.msg_dir == host", true),
        ("apt.dir == tx", true),
        ("ell.dir == tx", false),
    ] {
        assert_eq!(yes(&r, src), want, "{src}");
    }
}

#[test]
fn elliptec_fields_and_durations() {
    let r = ell_reply();
    for (src, want) in [
        ("ell.addr == 0", true),
        ("ell.addr == \"0\"", true),
        ("ell.cmd == PO", true),
        ("ell.cmd == po", false),
        ("ell.name == position", true),
        ("ell.module == ELL14", true),
        ("ell.module == ell14", true),
        ("ell.module.serial == 11400284", true),
        ("ell.fields.position == 35840", true),
        ("ell.position == 35840", true),
        ("ell.phys.position == 90", true),
        ("ell.phys.position.unit == deg", true),
        ("ell.pair == 12", true),
        ("pair == 12", true),
        ("paired", true),
        ("unpaired", false),
        ("apt.fields.position", false),
        ("apt.pair == 12", false),
        // latency is in ms: numbers are ms, durations convert.
        ("latency == 12.5", true),
        ("latency < 50ms", true),
        ("latency > 0.01s", true),
        ("latency > 12ms", true),
        ("latency <= 12500us", true),
        ("latency < 12500us", false),
        ("latency < 12500000ns", false),
        ("latency < 200us", false),
        ("latency < 2min", true),
        ("latency < 1h", true),
        ("latency > -1s", true),
        ("latency_ms == 12.5", true),
        ("ell.latency > 10ms", true),
        ("latency == 12.5ms", true),
        // ts is in seconds.
        ("ts == 2.5", true),
        ("ts > 2s", true),
        ("ts >= 2500ms", true),
        ("ts < 1.5s", false),
        ("ts < 1min", true),
        ("ts_ns == 2.5s", true),
        ("ts_ns == 2500000000", true),
        ("ell.fields.position < 1s", false),
    ] {
        assert_eq!(yes(&r, src), want, "{src}");
    }
}

#[test]
fn truthiness_and_specials() {
    let s = sub_rec();
    assert!(yes(&s, "apt.sub"));
    assert!(yes(&s, "apt.sub == SETPOINT"));
    assert!(yes(&s, "apt.sub == setpoint"));
    assert!(yes(&s, "apt.sub == 1"));
    assert!(yes(&s, "apt.sub.id == 1"));
    assert!(yes(&s, "apt.phys.setpoint == 5"));
    assert!(yes(&s, "apt.setpoint == 1638"));
    assert!(!yes(&status_rec(), "apt.sub"));
    assert!(!yes(&status_rec(), "apt.sub == SETPOINT"));
    assert!(!yes(&status_rec(), "apt.sub != SETPOINT"));

    let r = json!({"proto":"apt","n":1,"diag":[],"fields":{"position":0,"velocity":false,"model_number":"",
            "status_bits":[],"notes":"x","chan_ident":[1],"serial_number":null,"internal":{}}});
    assert!(yes(&r, "apt.fields.position"), "0 exists and is not false");
    assert!(!yes(&r, "apt.fields.velocity"));
    assert!(!yes(&r, "apt.fields.model_number"));
    assert!(!yes(&r, "apt.fields.status_bits"));
    assert!(yes(&r, "apt.fields.notes"));
    assert!(yes(&r, "apt.fields.chan_ident"));
    assert!(!yes(&r, "apt.fields.serial_number"));
    assert!(!yes(&r, "apt.fields.internal"));
    assert!(!yes(&r, "apt.fields.max_vel"));
    assert!(!yes(&r, "diag"));
    assert!(!yes(&r, "apt.fields.serial_number == null"));

    let input = json!({"type":"input","diag":[]});
    assert!(yes(&input, "diag"));
    assert!(!yes(&input, "apt.diag"), "an input record has no protocol");
    let garbage = json!({"proto":"apt","type":"garbage","diag":[]});
    assert!(yes(&garbage, "diag"));
    assert!(yes(&garbage, "apt.diag"));

    assert!(yes(&json!({"proto":"ell","unpaired":true}), "unpaired"));
    assert!(yes(
        &json!({"proto":"ell","unpaired":true}),
        "unpaired == true"
    ));
    assert!(!yes(&json!({"proto":"ell","unpaired":false}), "unpaired"));
    let unsol = json!({"proto":"ell","diag":[{"kind":"unsolicited","offset":3,"msg":"x"}]});
    assert!(yes(&unsol, "unpaired && diag"));
    assert!(yes(&unsol, "ell.unpaired"));
    assert!(!yes(&unsol, "apt.unpaired"));
    let unans = json!({"type":"diag","ref":3,"diag":[{"kind":"unanswered"}]});
    assert!(yes(&unans, "unpaired"));
    assert!(!yes(&json!({"pair":null}), "paired"));
    assert!(yes(&json!({"pair":0}), "paired"));
}

#[test]
fn values() {
    let r = json!({"proto":"apt","n":-3,"fields":{"model_number":"a \"quoted\" \\ word",
            "serial_number":18446744073709551615_u64,"position":-2147483648,"velocity":0.25,"notes":"x\ty"}});
    for (src, want) in [
        ("n == -3", true),
        ("n < -2", true),
        ("n == -0x3", true),
        (
            "apt.fields.model_number == \"a \\\"quoted\\\" \\\\ word\"",
            true,
        ),
        ("apt.fields.model_number contains \"\\\"quoted\\\"\"", true),
        ("apt.fields.notes == \"x\\ty\"", true),
        ("apt.fields.serial_number == 0xFFFFFFFFFFFFFFFF", true),
        ("apt.fields.serial_number == 18446744073709551615", true),
        ("apt.fields.serial_number > 18446744073709551614", true),
        ("apt.fields.position == -2147483648", true),
        ("apt.fields.velocity == 0.25", true),
        ("apt.fields.velocity < 1", true),
        ("apt.fields.velocity > 0", true),
        ("apt.fields.model_number ~ \"\\\"q\"", true),
    ] {
        assert_eq!(yes(&r, src), want, "{src}");
    }
    assert!(
        yes(&json!({"type":"frame"}), "   "),
        "blank filter matches all"
    );
    assert!(yes(&json!(null), ""));
    assert!(!yes(&json!(null), "apt"));
    assert!(!yes(&json!([1, 2]), "n == 1"));
    assert!(yes(&json!({"x": 1}), "!(n == 1)"));
}

#[test]
fn errors_point_at_their_column() {
    for (src, col, msg) in [
            ("apt.name ==", 12, "expected a value after `==`"),
            ("apt.name ==   && n", 15, "expected a value after `==`"),
            ("apt.name contains", 18, "expected a value after `contains`"),
            ("(apt.name == X", 1, "unbalanced parentheses: this `(` is never closed"),
            ("n == 1 && ((n == 2)", 11, "unbalanced parentheses: this `(` is never closed"),
            ("apt.name == X)", 14, "unbalanced parentheses: `)` without a matching `(`"),
            ("(n == 1 n)", 9, "expected `)`, `&&` or `||`, found `n`"),
            ("()", 2, "expected a test after `(`"),
            (
                "apt.name like X",
                10,
                "unknown operator `like` (use ==, !=, <, <=, >, >=, contains, ~, matches or in)",
            ),
            (
                "apt.name =~ X",
                10,
                "unknown operator `=~` (use ==, !=, <, <=, >, >=, contains, ~, matches or in)",
            ),
            ("apt.name = X", 10, "unknown operator `=` (did you mean `==`?)"),
            ("n == 1 & n == 2", 8, "unknown operator `&` (use `&&`)"),
            ("apt.sub | n == 2", 9, "unknown operator `|` (use ==, !=, <, <=, >, >=, contains, ~, matches or in)"),
            ("apt.name == \"MOT", 13, "unterminated string: missing closing `\"`"),
            ("apt.name == \"MOT\\\"", 13, "unterminated string: missing closing `\"`"),
            ("apt.name == X Y", 15, "unexpected `Y`: expected `&&`, `||` or the end of the filter"),
            ("apt.name ~ \"MOT_(\"", 12, "invalid regular expression: unclosed group"),
            ("apt.name matches \"[\"", 18, "invalid regular expression: unclosed character class"),
            ("latency < 50xs", 13, "unknown duration unit `xs` (use ns, us, ms, s, min or h)"),
            ("latency < 1.5sec", 14, "unknown duration unit `sec` (use ns, us, ms, s, min or h)"),
            ("n == 0x", 8, "expected hex digits after `0x`"),
            ("n == 0x1fz", 6, "bad hex number `0x1fz`"),
            ("n == 999999999999999999999999999999999999999999", 6, "number out of range"),
            (
                "name == MOT_MOVE_HOME",
                1,
                "unknown field `name`: protocol fields need a prefix; did you mean `apt.name`, `ell.name`?",
            ),
            (
                "dir == h2d && fields.position > 3",
                15,
                "unknown field `fields.position`: protocol fields need a prefix; did you mean `apt.fields.position`, `ell.fields.position`?",
            ),
            ("apt.nmae == X", 1, "unknown field `apt.nmae`; did you mean `apt.name`?"),
            (
                "frame.len > 3",
                1,
                "unknown field `frame.len`: protocol fields need a prefix; did you mean `len`?",
            ),
            (
                "ell.fields.postion > 3",
                1,
                "unknown field `ell.fields.postion`; did you mean `ell.fields.position`?",
            ),
            ("apt == 5", 1, "`apt` is a protocol; compare one of its fields, e.g. `apt.name`"),
            // The shape's value types (shape::Key::ty).
            ("n == abc", 6, "`n` is a number: `n == abc` can never hold"),
            ("len in {6 \"x\"}", 8, "`len` is a number: `len in x` can never hold"),
            ("interim > 0", 1, "`interim` is true or false: `>` does not apply (use == or !=)"),
            ("apt.diag < 2", 1, "`apt.diag` is a list: `<` does not apply (use == or !=)"),
            (
                "raw > 5",
                7,
                "`raw` is bytes (hex): compare it with hex text in quotes (`raw contains \"0500\"`)",
            ),
            ("apt.fields.", 12, "expected a field name after `.`"),
            ("n == 1 &&", 10, "expected a test after `&&`"),
            ("n == 1 ||   ", 13, "expected a test after `||`"),
            ("n == 1 and or", 12, "expected a test after `and`"),
            ("!", 2, "expected a test after `!`"),
            ("not", 4, "expected a test after `not`"),
            ("== 5", 1, "expected a field name, `!` or `(`, found `==`"),
            ("  \"x\"", 3, "expected a field name, `!` or `(`, found `\"`"),
            ("n in 5", 6, "expected `{` after `in`"),
            ("n in {1 2", 6, "unbalanced braces: this `{` is never closed"),
            ("n in {1 == }", 9, "expected a value or `}`, found `==`"),
            ("n == and", 6, "expected a value after `==`"),
        ] {
            let e = err(src);
            assert_eq!((e.column, e.msg.as_str()), (col, msg), "{src}");
        }
}

#[test]
fn error_display_and_caret() {
    let src = "apt.name ==";
    let e = err(src);
    assert_eq!(e.to_string(), "column 12: expected a value after `==`");
    assert_eq!(e.caret(src), "apt.name ==\n           ^");
    let src = "(dir == host";
    assert_eq!(err(src).caret(src), "(dir == host\n^");
    let src = "\tn == \"µs";
    let e = err(src);
    assert_eq!(e.column, 7);
    assert_eq!(e.caret(src), "\tn == \"µs\n\t     ^");
    let src = "n == 1 && µ";
    let e = err(src);
    assert_eq!(e.column, 11);
    assert_eq!(e.msg, "expected a test after `&&`");
}

#[test]
fn api_shape() {
    let flt: Filter = "apt.name == X".parse().expect("parses");
    assert_eq!(flt.as_str(), "apt.name == X");
    assert_eq!(flt.to_string(), "apt.name == X");
    let copy = flt.clone();
    assert!(format!("{copy:?}").contains("Cmp"));
    let e: Box<dyn std::error::Error> = Box::new(err("("));
    assert!(e.to_string().starts_with("column "));
}

#[test]
fn nesting_is_bounded() {
    let deep = format!("{}n == 1{}", "(".repeat(60), ")".repeat(60));
    assert!(f(&deep).matches(&json!({"n":1})));
    let too_deep = format!("{}n == 1{}", "(".repeat(500), ")".repeat(500));
    assert!(err(&too_deep).msg.contains("nested too deeply"));
    let nots = "!".repeat(10_000) + "n";
    assert!(err(&nots).msg.contains("nested too deeply"));
    let long = vec!["n == 1"; 20_000].join(" || ");
    assert!(f(&long).matches(&json!({"n":1})));
}

proptest::proptest! {
    #[test]
    fn never_panics(src in "\\PC{0,40}") {
        if let Ok(flt) = Filter::parse(&src) {
            for r in records(KDC101).iter().chain(records(DAMAGED).iter()) {
                let _ = flt.matches(r);
            }
        } else if let Err(e) = Filter::parse(&src) {
            proptest::prop_assert!(e.column >= 1 && e.column <= src.chars().count() + 1);
            let _ = e.caret(&src);
        }
    }

    #[test]
    fn never_panics_on_filter_like_text(
        parts in proptest::collection::vec(proptest::sample::select(vec![
            "apt.name", "n", "dir", "(", ")", "!", "&&", "||", "==", "<", "~", "in", "{", "}",
            "\"x", "\"a\"", "0x", "12ms", "-", "contains", "HOMED", " ", ".", "ell.", "diag",
        ]), 0..12)
    ) {
        let src: String = parts.concat();
        match Filter::parse(&src) {
            Ok(flt) => {
                for r in records(ELL_BUS) {
                    let _ = flt.matches(&r);
                }
            }
            Err(e) => {
                proptest::prop_assert!(e.column >= 1 && e.column <= src.chars().count() + 1);
            }
        }
    }
}
