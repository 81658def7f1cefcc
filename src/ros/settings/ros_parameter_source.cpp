#include "mild_lcd/ros/settings/ros_parameter_source.hpp"

#include "mild_lcd/common/errors.hpp"

namespace mild_lcd {
namespace {

const char* typeName(const XmlRpc::XmlRpcValue& v) {
  switch (v.getType()) {
    case XmlRpc::XmlRpcValue::TypeBoolean:
      return "a boolean";
    case XmlRpc::XmlRpcValue::TypeInt:
      return "an integer";
    case XmlRpc::XmlRpcValue::TypeDouble:
      return "a number";
    case XmlRpc::XmlRpcValue::TypeString:
      return "a string";
    case XmlRpc::XmlRpcValue::TypeArray:
      return "a list";
    case XmlRpc::XmlRpcValue::TypeStruct:
      return "a map";
    default:
      return "an unsupported value";
  }
}

mild::InvalidInput wrongType(const ros::NodeHandle& nh, const std::string& name, const char* expected,
                             const XmlRpc::XmlRpcValue& v) {
  return mild::InvalidInput("parameter " + nh.resolveName(name) + " must be " + expected + ", got " + typeName(v));
}

}  // namespace

std::optional<XmlRpc::XmlRpcValue> RosParameterSource::get(const std::string& name) const {
  XmlRpc::XmlRpcValue v;
  if (!nh_.getParam(name, v)) return std::nullopt;
  return v;
}

std::optional<double> RosParameterSource::getDouble(const std::string& name) const {
  auto v = get(name);
  if (!v) return std::nullopt;
  if (v->getType() == XmlRpc::XmlRpcValue::TypeDouble) return static_cast<double>(*v);
  if (v->getType() == XmlRpc::XmlRpcValue::TypeInt) return static_cast<double>(static_cast<int>(*v));
  throw wrongType(nh_, name, "a number", *v);
}

std::optional<int64_t> RosParameterSource::getInt(const std::string& name) const {
  auto v = get(name);
  if (!v) return std::nullopt;
  if (v->getType() == XmlRpc::XmlRpcValue::TypeInt) return static_cast<int>(*v);
  // Large values (expected_features) do not fit XML-RPC's 32-bit ints and arrive as doubles.
  if (v->getType() == XmlRpc::XmlRpcValue::TypeDouble) {
    const double d = static_cast<double>(*v);
    if (d == static_cast<double>(static_cast<int64_t>(d))) return static_cast<int64_t>(d);
  }
  throw wrongType(nh_, name, "an integer", *v);
}

std::optional<bool> RosParameterSource::getBool(const std::string& name) const {
  auto v = get(name);
  if (!v) return std::nullopt;
  if (v->getType() == XmlRpc::XmlRpcValue::TypeBoolean) return static_cast<bool>(*v);
  throw wrongType(nh_, name, "true or false", *v);
}

std::optional<std::string> RosParameterSource::getString(const std::string& name) const {
  auto v = get(name);
  if (!v) return std::nullopt;
  if (v->getType() == XmlRpc::XmlRpcValue::TypeString) return static_cast<std::string>(*v);
  throw wrongType(nh_, name, "a string", *v);
}

std::optional<std::vector<double>> RosParameterSource::getDoubleList(const std::string& name) const {
  auto v = get(name);
  if (!v) return std::nullopt;
  if (v->getType() != XmlRpc::XmlRpcValue::TypeArray) throw wrongType(nh_, name, "a list of numbers", *v);
  std::vector<double> out;
  for (int i = 0; i < v->size(); ++i) {
    XmlRpc::XmlRpcValue& item = (*v)[i];
    if (item.getType() == XmlRpc::XmlRpcValue::TypeDouble) {
      out.push_back(static_cast<double>(item));
    } else if (item.getType() == XmlRpc::XmlRpcValue::TypeInt) {
      out.push_back(static_cast<int>(item));
    } else {
      throw wrongType(nh_, name, "a list of numbers", *v);
    }
  }
  return out;
}

std::vector<std::string> RosParameterSource::names() const {
  std::vector<std::string> all;
  nh_.getParamNames(all);
  const std::string prefix = nh_.getNamespace() == "/" ? "/" : nh_.getNamespace() + "/";
  std::vector<std::string> out;
  for (const std::string& n : all) {
    if (n.compare(0, prefix.size(), prefix) == 0) out.push_back(n.substr(prefix.size()));
  }
  return out;
}

}  // namespace mild_lcd
